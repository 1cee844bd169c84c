"""The relight verbs' work, one function each (bpy: they read the bake records on objects): an
object's texture bake relit under a sun or an environment, a per-vertex bake shaded. The CLI
parses the arguments, calls these and prints; a script or a test calls them the same way.
Bad input raises :class:`...lt_addon.errors.InputError` with the message the CLI prints."""

from __future__ import annotations

import os

import numpy as np

from ...lt_addon.errors import InputError
from ...lt_addon.sphere.hemisphere import direction_from_az_el
from ...lt_addon.transport import bundle
from ..base.blend_files import bake_file, object_bakes
from . import vertex_relight

LOBES_KIND = "steerable_texture"


def texture_kind(obj, environment: bool = False) -> str:
    """Which texture bake of ``obj`` a relight uses: the latest of its transport and lobes
    bakes; under an ``environment`` a transport bake whenever there is one (the lobes kind when
    there is neither: reading it then says what is missing)."""
    kinds = [b.get("kind") for b in object_bakes(obj) if b.get("kind") in (bundle.KIND,
                                                                          LOBES_KIND)]
    if environment and bundle.KIND in kinds:
        return bundle.KIND
    return kinds[-1] if kinds else LOBES_KIND


def relight_texture(obj, *, light=None, env_path: str | None = None, rotate: float = 0.0,
                    sun_angle: float | None = None, intensity: float = 1.0,
                    color=(1.0, 1.0, 1.0), source: str = "viewport") -> tuple:
    """``obj``'s texture relit: radiance (R, R, 3) float32 and what was done (a dict).

    ``light`` (azimuth, elevation) in degrees, or ``env_path`` an equirectangular EXR turned by
    ``rotate`` degrees like a world Mapping node (transport bakes; their direct light from T or
    the model, ``source``: by default what the viewport shows for it, and the indirect term
    steered by the same light). ``sun_angle``: the
    sun's size (default: the bake's); ``intensity`` the sun's normal irradiance or the
    environment's scale; ``color`` an RGB tint."""
    if (light is None) == (env_path is None):
        raise InputError("give exactly one of --light AZ,EL and --env HDR.exr")
    kind = texture_kind(obj, environment=env_path is not None)
    if kind == LOBES_KIND:
        if env_path is not None:
            raise InputError(f"{obj.name}'s bake is a lobes bake; --env needs a transport bake "
                             "(bake-textures --method transport)")
        from ...lt_addon.steerable.texture import SteerableTexture

        try:
            texture = SteerableTexture.load(bake_file(obj, LOBES_KIND, "steerable texture"))
        except (FileNotFoundError, ValueError) as exc:
            raise InputError(str(exc)) from None
        img = texture.relight(direction_from_az_el(*light), intensity, color)
        return img, {"object": obj.name, "light": list(light), "light_azimuth": light[0],
                     "light_elevation": light[1], "intensity": intensity, "color": list(color),
                     "source": texture.settings}
    try:
        bake, store, report = bundle.load_bake(bake_file(obj, bundle.KIND, "transport texture"))
    except (FileNotFoundError, ValueError, KeyError) as exc:
        raise InputError(str(exc)) from None
    angle = report["settings"]["sun_angle"] if sun_angle is None else sun_angle
    if not 0.0 <= angle <= 90.0:
        raise InputError(f"--sun-angle must be in 0..90 degrees, got {angle}")
    if source == "viewport":   # what the panel shows for this object (the report's figure)
        source = bundle.viewport_source(bake, environment=env_path is not None)
    info = {"object": obj.name, "method": "transport"}
    if env_path is not None:
        from ...lt_addon.export.fitting import read_environment

        env_path = os.path.abspath(env_path)
        env = read_environment(env_path)                 # row 0 at the bottom (exrio)
        img = bundle.relight_environment(bake, store, env, -rotate,   # Mapping convention
                                         row_order="bottom_first", source=source)
        img = img * intensity * np.asarray(color, np.float32)
        info.update(env=env_path, rotate=rotate, source=source,
                    indirect=("steered by the environment" if bake.indirect is not None
                              else "none baked (bounces 0)"))
    else:
        img = bundle.relight(bake, store, direction_from_az_el(*light), angle, intensity,
                             source=source, kernel=report["settings"].get("kernel", "linear"))
        img = img * np.asarray(color, np.float32)
        info.update(light=list(light), sun_angle=angle, source=source)
    return img, info


def relight_vertices(scene, obj, *, env=None, point_light=None, rotate: float = 0.0) -> tuple:
    """``obj``'s per-vertex bake shaded: radiance (V, 3) float32, what was done, and warnings.

    ``env``: an equirectangular image (H, W, 3), else the scene world's (turned by its Mapping
    rotation, as the preview is) unless only ``point_light`` (position, power) lights it;
    ``rotate`` degrees more about +z."""
    warnings, world_z = [], 0.0
    if env is None and point_light is None:
        env = vertex_relight.world_environment(scene)
        if env is None:
            raise InputError("the scene world has no environment image or colour; pass --env")
        world_z, note = vertex_relight.world_rotation(scene)
        if note:
            warnings.append(note)
    try:
        data = vertex_relight.transport_data(obj)
    except (ValueError, FileNotFoundError) as exc:
        raise InputError(str(exc)) from None
    light = None
    if point_light is not None:
        light = (np.array(point_light[0]), point_light[1], (1.0, 1.0, 1.0))
    values, said = vertex_relight.shade(data, env, vertex_relight.shade_rotation(world_z + rotate),
                                        1.0, light)
    values = values.astype(np.float32)
    info = {"object": obj.name, "vertices": int(values.shape[0]), "d": data.model.d,
            "mean": [float(v) for v in values.mean(axis=0)]}
    return values, info, warnings + said
