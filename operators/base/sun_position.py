"""The place a .blend's *Sun Position* add-on holds, for sun studies (bpy; issue 58).

Blender's *Sun Position* add-on (an extension since 4.2) keeps its settings on the scene as
``scene.sun_pos_properties``: ``latitude`` and ``longitude`` (degrees, north and east
positive), ``UTC_zone`` (hours), ``use_daylight_savings`` (one hour more, all year) and
``north_offset`` (radians, the scene's north turned from +Y towards +X... as the add-on turns
it). :func:`read` returns them where the file holds them, whether or not the add-on is enabled
here: when it is not (the venv CLI has no extensions), a reader with the same property names
is registered for the moment of reading -- Blender keeps an unregistered add-on's settings in
the file and shows them to a property group of the same names -- and unregistered again.
Nothing the file names is run; only these five numbers are read.
"""

from __future__ import annotations

import bpy

PROPERTY = "sun_pos_properties"
FIELDS = ("latitude", "longitude", "UTC_zone", "use_daylight_savings", "north_offset")


class RelightSunPosReader(bpy.types.PropertyGroup):
    """The Sun Position add-on's place settings, by their names (read-only use)."""

    latitude: bpy.props.FloatProperty()
    longitude: bpy.props.FloatProperty()
    UTC_zone: bpy.props.FloatProperty()
    use_daylight_savings: bpy.props.BoolProperty()
    north_offset: bpy.props.FloatProperty()


def _values(group) -> dict | None:
    if not any(group.is_property_set(f) for f in ("latitude", "longitude", "UTC_zone")):
        return None     # the add-on's defaults only: no place was set
    return {f: (bool(getattr(group, f)) if f == "use_daylight_savings"
                else float(getattr(group, f))) for f in FIELDS}


def read(scene) -> dict | None:
    """``{latitude, longitude, UTC_zone, use_daylight_savings, north_offset}`` of the *Sun
    Position* add-on's settings on ``scene``, or None when the scene holds none."""
    if PROPERTY in bpy.types.Scene.bl_rna.properties:     # the add-on is enabled here
        group = getattr(scene, PROPERTY, None)
        return _values(group) if group is not None else None
    bpy.utils.register_class(RelightSunPosReader)
    try:
        setattr(bpy.types.Scene, PROPERTY, bpy.props.PointerProperty(type=RelightSunPosReader))
        try:
            return _values(getattr(scene, PROPERTY))
        finally:
            delattr(bpy.types.Scene, PROPERTY)
    finally:
        bpy.utils.unregister_class(RelightSunPosReader)


def write_for_tests(scene, **values) -> None:
    """Store *Sun Position* settings on ``scene`` the way the add-on does (its property names),
    without the add-on: for tests and samples. ``values``: any of :data:`FIELDS`."""
    bpy.utils.register_class(RelightSunPosReader)
    try:
        setattr(bpy.types.Scene, PROPERTY, bpy.props.PointerProperty(type=RelightSunPosReader))
        try:
            group = getattr(scene, PROPERTY)
            for k, v in values.items():
                setattr(group, k, v)
        finally:
            delattr(bpy.types.Scene, PROPERTY)
    finally:
        bpy.utils.unregister_class(RelightSunPosReader)
