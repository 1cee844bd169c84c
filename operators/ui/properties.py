"""Scene-level settings of the extension (``scene.relight``)."""

from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ...samples import DESCRIPTIONS, SIZES
from ..base.compat import path_options
from ..bakes.presets import PRESET_NAMES, TRANSPORT, settings_from_preset
from ..farm.external_bake import ADDON_ID, RUN_ON as _RUN_ON, SCHEDULER_TRUST, WHERE
from .settings_props import properties, values

_SETTING_NAMES = ("frame", "order", "resolution", "samples", "bounces", "storage", "mode",
                  "world_sampling")


def preset_values(method: str, preset: str) -> dict:
    """The panel fields a preset sets, by property name (what :func:`_apply_preset` writes and
    what :func:`preset_differences` compares)."""
    if method == "lobes":
        lobes = settings_from_preset(preset)
        return {name: getattr(lobes, name) for name in _SETTING_NAMES}
    t = TRANSPORT.settings(preset)
    count, _, power = t.directions.partition(":")[2].partition(":")
    return {"directions": int(count), "horizon_power": float(power or 1.0),
            "resolution": t.resolution, "transport_tol": t.tol,
            "transport_components": int(t.components or 0),
            "indirect_samples": t.indirect_samples,
            "indirect_resolution": t.indirect_resolution, "table_size": t.table_size,
            "horizon_azimuths": t.horizon_azimuths, "horizon_resolution": t.horizon_resolution}


def measured_values(method: str, preset: str) -> dict:
    """The panel fields as the preset's figures were measured: the preset's own values and, for
    the transport method, the declared defaults of the fields it leaves alone (Model, Viewport,
    Indirect Light, ...), by property name. Sun Size, Check vs Cycles, Output and the device
    are not in it (the figures are chosen by Sun Size; the rest do not change the result)."""
    values = preset_values(method, preset)
    if method != "transport":
        return values
    from ...lt_addon.settings import declared
    from ..bakes.texture_transport import TransportTextureSettings

    # the figures were measured with 2 bounces (a scene's own are the scene's: the toggle
    # Scene's Light Paths is not a difference from the preset)
    values["bounces"] = 2
    for s in declared(TransportTextureSettings, TRANSPORT_FIELDS):
        prop = TRANSPORT_PROPS.get(s.name, s.name)
        if prop not in values:
            values[prop] = (str(s.default) if s.choices else
                            int(s.default or 0) if s.kind == "int" else s.default)
    return values


def preset_differences(props) -> list:
    """Names of the fields that no longer hold the values the chosen preset was measured with
    (the panel then says "Custom" instead of showing the preset's measured figures)."""
    out = []
    for name, value in measured_values(props.method, props.preset).items():
        mine = getattr(props, name)
        if (abs(mine - value) > 1e-6 * max(1.0, abs(value)) if isinstance(value, float)
                else mine != value):
            out.append(name)
    return out


def ui_label(props, name: str) -> str:
    """The panel's label of property ``name`` (what the user reads, never the identifier)."""
    prop = props.bl_rna.properties.get(name)
    return prop.name if prop is not None and prop.name else name.replace("_", " ").title()


#: The Sun Sizes (degrees) the presets' figures were measured at, by figure key.
FIGURE_SUNS = {"rel_rmse_0526deg": 0.526, "rel_rmse_2deg": 2.0, "rel_rmse": 10.0}


def measured_line(method: str, preset: str, sun_angle: float) -> str | None:
    """The preset's measured cost and error against Cycles for the Sun Size in use (the figure
    of the nearest size measured, said when it is not the same), or None when the preset has no
    measured figures."""
    from ..bakes.presets import BY_METHOD

    fig = BY_METHOD[method].figures(preset)
    keys = [k for k in FIGURE_SUNS if k in fig]
    if not fig or not keys:
        return None
    key = min(keys, key=lambda k: abs(FIGURE_SUNS[k] - sun_angle))
    at = FIGURE_SUNS[key]
    where = f"{fig.get('scene', '?')}, {fig.get('machine', '?')}"
    same = abs(at - sun_angle) < 1e-6
    return (f"Measured: {fig['bake_seconds']:.1f} s, error {fig[key]:.3f} vs Cycles at a "
            f"{at:g}\u00b0 sun" + ("" if same else f" (Sun Size is {sun_angle:g}\u00b0)")
            + f" ({where})")


def _preset_items():
    """The Preset menu with a tooltip per preset: what it is for and what the transport bake
    (the default method) does with it, with its measured cost and error where measured."""
    from ..bakes.presets import TRANSPORT

    use = {"draft": "Quickest: to try the light, framing and resolution",
           "balanced": "The default: sharp shadows at a few seconds per object",
           "production": "Most accurate: for final results, several times the balanced cost"}
    items = []
    for name in PRESET_NAMES:
        v, fig = TRANSPORT.values(name), TRANSPORT.figures(name)
        count = str(v.get("directions", "")).split(":")[1:2]
        text = (f"{use.get(name, name.capitalize())}. Transport: {count[0] if count else '?'} "
                f"sun directions at {v.get('resolution', '?')}x{v.get('resolution', '?')}")
        if fig.get("bake_seconds") is not None and fig.get("rel_rmse_2deg") is not None:
            text += (f"; measured {fig['bake_seconds']:.0f} s and {fig['rel_rmse_2deg']:.3f} "
                     f"from Cycles at a 2 degree sun ({fig.get('scene', '?')})")
        items.append((name, name.capitalize(), text))
    return items


def _apply_preset(self, context):
    for name, value in preset_values(self.method, self.preset).items():
        setattr(self, name, value)


def _scale_with_resolution(self, context):
    """A new texture side moves the transport fields a preset scales with it (the indirect
    grid: ``presets.scaled``) to the chosen preset's values at that side,
    where they still hold one of the preset's values at some side (a value of one's own
    stays)."""
    from ..bakes.presets import scaled

    if self.method != "transport":
        return
    base = TRANSPORT.values(self.preset)
    sides = [base["resolution"] << i for i in range(8)]
    family = {k: {scaled(base, r, TRANSPORT.scales)[k] for r in sides}
              for k in TRANSPORT.scales if k in base}
    for k, v in scaled(base, self.resolution, TRANSPORT.scales).items():
        if getattr(self, k) in family[k] and getattr(self, k) != v:
            setattr(self, k, v)


#: New scenes start on the balanced presets (transport, the default method, for the shared
#: resolution), so the preset shown is the one the fields hold.
_LOBES = preset_values("lobes", "balanced")
_TRANSPORT = preset_values("transport", "balanced")


def preview_sun_angle(scene) -> tuple[float, str]:
    """``(degrees, where from)``: the Sun Size the panel's bakes and previews use. With
    *Scene's Sun* (the default) the angle of the scene's first rendered Sun, as Cycles renders
    it (Blender's default 0.526), or 2 without a Sun -- what ``bake-textures`` takes by default
    (:func:`..bakes.texture_transport.scene_light_settings`); else the *Sun Size* field."""
    from ..base.scene_sun import DEFAULT_SUN_ANGLE, scene_sun_angle, scene_suns

    props = scene.relight
    if not props.scene_sun_size:
        return float(props.sun_angle), "Sun Size"
    angle = scene_sun_angle(scene)      # (the bake's own reading, rounded as it rounds it)
    if angle is None:
        return DEFAULT_SUN_ANGLE, "the scene has no Sun"
    return round(angle, 4), f"the scene's Sun {scene_suns(scene)[0].name}"


def _refresh_tables(self, context):
    """A new sun size only changes the preview's coefficient tables (no re-bake)."""
    from ..preview.transport_preview import refresh_preview_tables

    obj = context.active_object if context is not None else None
    if obj is not None:
        refresh_preview_tables(context.scene, obj, preview_sun_angle(context.scene)[0])


def _sun_poll(self, obj):
    return obj.type == "LIGHT" and obj.data.type == "SUN"


def _point_poll(self, obj):
    return obj.type == "LIGHT" and obj.data.type == "POINT"


def _refresh_vertex_preview(self, context):
    from ..preview.transport_preview import update_environment_previews
    from ..preview.vertex_relight import update_preview

    update_preview(context.scene)
    update_environment_previews(context.scene)


def _on_texture_light(self, context):
    from ..preview.transport_preview import set_light_mode

    for obj in context.scene.objects:
        if obj.type == "MESH":
            set_light_mode(context.scene, obj, self.texture_light)


def _get_check(self) -> bool:
    """Check vs Cycles: the stored tick, or for a file of an older version (an integer count
    only) whether its count is above 0."""
    stored = self.get("check_vs_cycles")
    if stored is not None:
        return bool(stored)
    count = self.get("truth_lights")
    return bool(count) and int(count) > 0


def _set_check(self, value: bool) -> None:
    self["check_vs_cycles"] = bool(value)
    if value and self.truth_lights < 1:
        self.truth_lights = 4


def truth_count(props) -> int:
    """Held-out lights a bake checks against Cycles: the count when Check vs Cycles is ticked,
    else 0."""
    return int(props.truth_lights) if props.check_vs_cycles else 0


def _on_show_preview(self, context):
    from ..preview.preview_nodes import set_previews_shown

    scene = context.scene if context is not None else None
    if scene is not None:
        set_previews_shown(list(scene.objects), self.show_preview)


#: Output folders the user set in this Blender session (normalised absolute paths), filled by
#: the Output field's update callback -- Blender calls it when the field is edited (in the UI or
#: by a script), never when a file is loaded. A bake uses a folder a .blend names outside that
#: .blend's own folder only when it is one of these (:func:`.bake_ops._output_dir`).
CONFIRMED_OUTPUT_DIRS: set = set()


def _confirm_output_dir(self, context):
    """The user chose this Output folder in this session: remember it (resolved against the
    open .blend now; a '//' path of an unsaved file has no folder yet and is not kept)."""
    if not self.output_dir:
        return     # the default folder (one rule with the CLI: bake_ops.default_output_dir)
    path = bpy.path.abspath(self.output_dir)
    if not path.startswith("//") and os.path.isabs(path):
        CONFIRMED_OUTPUT_DIRS.add(os.path.normpath(path))


class RelightSceneSettings(bpy.types.PropertyGroup):
    """Settings shown in the Relight sidebar tab."""

    sample_name: EnumProperty(
        name="Sample", description="Sample scene to add",
        items=[(k, k.capitalize(), v) for k, v in DESCRIPTIONS.items()], default="bumps")
    sample_size: EnumProperty(
        name="Size", description="Sample scene size",
        items=[(s, s.capitalize(), {"test": "Small and quick (the tests' size)",
                                    "demo": "The size the documentation's pictures use"}.get(
                    s, f"{s} size")) for s in SIZES], default="demo")

    preset: EnumProperty(
        name="Preset",
        description="Starting values for the bake settings, each measured for its cost and its "
                    "error against Cycles",
        items=_preset_items(), default="balanced", update=_apply_preset)
    output_dir: StringProperty(
        name="Output", subtype="DIR_PATH", default="", options=path_options(),
        update=_confirm_output_dir,
        description="Folder for the bake's files. Empty: <file>_relight next to the .blend, "
                    "as the command line does (an unsaved file: relight/untitled-<time>_relight "
                    "in your home folder; the panel says which). A bake writes, replaces and "
                    "removes its files there, so a folder saved in a .blend is used only inside "
                    "that .blend's folder; any other must be chosen here in this session")
    sun: PointerProperty(name="Sun", type=bpy.types.Object, poll=_sun_poll,
                         description="Sun lamp whose direction the preview follows")

    texture_light: EnumProperty(
        name="Light", default="SUN", update=_on_texture_light,
        description="What lights the transport-texture previews",
        items=[("SUN", "Sun", "The Preview Light sliders, or the followed Sun lamp (no Python "
                              "per change)"),
               ("WORLD", "World", "The world's Environment Texture, turned by its Mapping Z "
                                  "rotation plus Environment Rotation, times Environment "
                                  "Strength (a few ms of Python per change)")])

    # per-vertex (eigentransport) preview: NumPy shading written into one colour attribute
    env_strength: FloatProperty(
        name="Environment Strength", default=1.0, min=0.0, soft_max=10.0,
        description="Scale of the world environment lighting the vertex preview and the "
                    "texture previews lit by the World",
        update=_refresh_vertex_preview)
    env_rotation: FloatProperty(
        name="Environment Rotation", default=0.0, soft_min=-180.0, soft_max=180.0,
        description="Rotation of the environment about +z in degrees, the same way as a world "
                    "Mapping node's Z rotation, added to it (lattice rotation, Nowrouzezahrai "
                    "2008 sec. 5)", update=_refresh_vertex_preview)
    point_light: PointerProperty(
        name="Point Light", type=bpy.types.Object, poll=_point_poll,
        description="A point lamp added to the vertex preview (nearest sample direction, "
                    "1/r^2; valid outside the object's convex hull)",
        update=_refresh_vertex_preview)
    show_clusters: BoolProperty(
        name="Show Clusters", default=False,
        description="Colour the vertices by CPCA cluster (bake-transport --clusters) instead "
                    "of the shading", update=_refresh_vertex_preview)

    # direction-sampled transport textures (the default texture bake)
    method: EnumProperty(
        name="Method", default="transport", update=_apply_preset, items=[
            ("transport", "Transport (hard suns)",
             "Bake under S hard Sun lamps and relight any sun or sky from them: sharp shadows"),
            ("lobes", "Steerable lobes",
             "The paper's bake under order^2 broad steerable lights: soft (~27 degree) light")])
    directions: IntProperty(
        name="Directions", default=_TRANSPORT["directions"], min=8, max=100000,
        description="Hard-sun bakes over the upper hemisphere (1 sample each)")
    horizon_power: FloatProperty(
        name="Horizon Density", default=_TRANSPORT["horizon_power"], min=1.0, max=4.0,
        description="1: uniform over the hemisphere; above 1: more directions near the horizon, "
                    "where grazing shadows change fastest")
    scene_bounces: BoolProperty(
        name="Scene's Light Paths", default=True,
        description="Bake the interreflections with the bounces the scene renders with (Render "
                    "> Light Paths: Diffuse, capped by Total), as Cycles renders it; off: the "
                    "Bounces below")
    scene_sun_size: BoolProperty(
        name="Scene's Sun", default=True, update=_refresh_tables,
        description="Bake and preview with the Sun Size of the scene's Sun (its Angle: "
                    "Blender's default is 0.526 degrees), as Cycles renders the scene; 2 "
                    "degrees when it has no Sun; off: the Sun Size below")
    sun_angle: FloatProperty(
        name="Sun Size", default=2.0, min=0.0, max=30.0, update=_refresh_tables,
        description="Angular diameter of the preview sun in degrees, when Scene's Sun is off "
                    "(re-tabulates the preview coefficients, no re-bake)")
    # material edits (transfer tensors, Sun 2007)
    material_per_corner: BoolProperty(
        name="Per Face Corner", default=False,
        description="A value per face corner instead of per vertex: hard edges (a box's) stay "
                    "hard, for about 4x the data and update time on quad meshes")
    material_directions: IntProperty(
        name="Direct Directions", default=400, min=4, max=100000,
        description="Hard-sun directions of the direct light (1 sample each: exact)")
    material_one_directions: IntProperty(
        name="1-Bounce Directions", default=128, min=2, max=10000,
        description="Sun directions of the one-bounce terms (with Cycles bounces one bake per "
                    "region each; with rays free, and a sun between them is made exact)")
    material_two_directions: IntProperty(
        name="2-Bounce Directions", default=8, min=2, max=10000,
        description="Sun directions of the stored two-bounce terms (with Cycles bounces "
                    "(R+1) + (R+1)^2 bakes each); the second bounce is composed from the first "
                    "where the one-bounce directions are at least 16 and twice as many")
    material_anchors: StringProperty(
        name="Roughness Anchors", default="",
        description="Comma-separated roughness values (e.g. 0.4,0.8) at which each editable "
                    "material is also baked as a metal, so its Metallic and Roughness can be "
                    "edited live (one more one-bounce bake per material, value and direction). "
                    "Empty: colour edits only")
    material_anchor_directions: IntProperty(
        name="Anchor Directions", default=128, min=2, max=10000,
        description="Sun directions of the glossy anchors' bakes (one Cycles bake per material, "
                    "anchor and direction)")
    # export (relight export): directional lightmaps and RTI models of a transport bake
    export_terms: EnumProperty(name="Terms", default="9", items=[
        ("4", "4", "HSH order 2"), ("9", "9", "HSH order 3 (OpenLIME evaluates at most 9)")])
    export_light: EnumProperty(name="Lighting", default="SUN", items=[
        ("SUN", "Preview Light", "A sun from the Preview Light sliders"),
        ("ENV", "Environment", "An equirectangular EXR")])
    export_env: StringProperty(name="Environment", subtype="FILE_PATH",
                               options=path_options(),
                               description="Equirectangular RGB EXR lighting the lightmap")
    export_env_rotation: FloatProperty(
        name="Rotation", default=0.0, soft_min=-180.0, soft_max=180.0,
        description="The environment's rotation about +z, as a world Mapping node's Z")
    export_force: BoolProperty(name="Replace Existing", default=False,
                               description="Replace an earlier export of this object and format")
    sun_study_folder: StringProperty(
        name="Study", subtype="DIR_PATH", default="", options=path_options(),
        description="A folder relight sun-study wrote (its sun_study.json and maps); only "
                    "read, never written")
    sun_study_hours: StringProperty(
        name="Hours", default="9,12,15",
        description="Run Sun Study: the clock hours of each date of Sun Study (each counts one "
                    "hour, e.g. 9,12,15 or 9:30), the cells of its shadow-study sheet")
    sun_study_step: IntProperty(
        name="Every (min)", default=0, min=0, max=240,
        description="Run Sun Study: 0 takes the Hours; more takes an instant every so many "
                    "minutes through each day instead (each counts its step: real sunlight "
                    "hours)")
    sun_study_radiation: BoolProperty(
        name="Radiation", default=True,
        description="Run Sun Study: also the clear-sky solar radiation map (kWh/m2)")
    sun_study_weather: StringProperty(
        name="Weather", subtype="FILE_PATH", default="", options=path_options(),
        description="An EnergyPlus weather file (.epw): the radiation map from its hourly "
                    "direct and diffuse radiation instead of a clear sky (implies Radiation; "
                    "the study's dates by month and day)")
    sun_study_map: EnumProperty(name="Map", default="hours", items=[
        ("hours", "Sunlight Hours", "Hours of direct sun per texel over the study"),
        ("radiation", "Radiation", "Solar radiation in kWh/m2, clear sky or a weather file's "
                                   "(a study run with Radiation, --radiation or --weather)")])

    # which device Cycles bakes on (operators/base/cycles_device.py), and the last bake's
    device: EnumProperty(name="Device", default="auto", items=[
        ("auto", "Auto", "The GPU chosen in Preferences > System when the scene's Cycles device "
                          "is GPU, else the CPU (the bake says which)"),
        ("cpu", "CPU", "Always the CPU"),
        ("gpu", "GPU", "The GPU of Preferences > System (or the first Cycles finds); refuses "
                        "to bake without one")])
    mix_devices: BoolProperty(
        name="Mix Devices", default=False,
        description="Resume from chunks an interrupted bake left on another device (CPU and GPU "
                    "bake one seed as different sample sets, so the result mixes two); off: "
                    "those chunks are baked again")
    device_used: StringProperty(name="Baked On", default="",
                                description="The device the last bake of this scene used")

    # where a bake runs (operators/farm/external_bake.py): here, or through `relight` on Dask
    run_on: EnumProperty(name="Run On", default="HERE", items=[
        (k, label, desc) for k, label, desc in _RUN_ON])
    dask_workers: IntProperty(
        name="Workers", default=2, min=1, max=256,
        description="Worker processes of the local Dask cluster (each gets its share of the "
                    "cores as Cycles threads)")
    # legacy: a .blend of an older version may carry these; they are never used (a received
    # file must not choose a program to run or a cluster to trust) -- the Relight Command and
    # the Dask Scheduler are the add-on's preferences (RelightPreferences); the panel says a
    # non-empty one is ignored
    dask_scheduler: StringProperty(
        name="Scheduler (ignored)", default="",
        description="Legacy, ignored: the Dask Scheduler is set in " + WHERE)
    dask_command: StringProperty(
        name="Relight Command (ignored)", default="",
        description="Legacy, ignored: the Relight Command is set in " + WHERE)

    truth_lights: IntProperty(
        name="Lights", default=4, min=0, max=12,
        description="How many held-out Sun directions Check vs Cycles renders with Cycles (each "
                    "a full Cycles bake of the objects: the check's cost)")
    check_vs_cycles: BoolProperty(
        name="Check vs Cycles", get=_get_check, set=_set_check,
        description="After the bake, bake Cycles with a real Sun at a few held-out directions "
                    "and report how far the preview is from it (costs one Cycles bake per "
                    "light)")
    show_preview: BoolProperty(
        name="Show Preview", default=True, update=_on_show_preview,
        description="Show the relit preview in EEVEE (Material Preview). Off: your own "
                    "materials in every view. Renders (F12) and bakes use your materials (EEVEE "
                    "renders from the UI with Lock Interface on)")


# The bakes' own settings, declared once on their dataclasses (lt_addon/settings.py): the lobes
# bake's, the two the methods share (one field each in the panel), and the transport bake's
# (a transport_ prefix where the word is ambiguous). New scenes hold the balanced presets.
#: Panel property of each transport setting whose name alone would be ambiguous.
TRANSPORT_PROPS = {"model": "transport_model", "viewport": "transport_viewport",
                   "direct": "transport_direct", "indirect": "transport_indirect",
                   "tol": "transport_tol", "components": "transport_components"}
#: Panel property of each declared per-vertex bake setting (the Vertex Transport box).
VERTEX_FIELDS = ("directions", "bounces", "direct", "energy")
VERTEX_PROPS = {f: "vertex_" + f for f in VERTEX_FIELDS}
#: Panel property of each declared material-bake setting (the panel's Material Edits box).
MATERIAL_FIELDS = ("bounces", "direct", "bounce_bake", "rays", "samples", "anchor_samples",
                   "smoothing")
MATERIAL_PROPS = {f: "material_" + f for f in MATERIAL_FIELDS}
LOBES_FIELDS = ("frame", "order", "samples", "storage", "mode", "world_sampling")
TRANSPORT_FIELDS = ("direct", "texel_sampling", "sun_path", "sun_path_step", "study",
                    "under_horizon", "model",
                    "viewport",
                    "horizon_azimuths", "horizon_resolution", "gpu_budget",
                    "tol",
                    "components", "indirect", "indirect_rays", "indirect_components",
                    "indirect_samples", "indirect_resolution", "table_size")


def _declared_properties() -> dict:
    from ..bakes.steerable_bake import TextureBakeSettings
    from ..bakes.export import ExportSettings
    from ..bakes.material_bake import MaterialBakeSettings
    from ..bakes.texture_transport import TransportTextureSettings
    from ..bakes.transport_bake import TransportSettings

    return {**properties(TextureBakeSettings, LOBES_FIELDS, defaults=_LOBES),
            **properties(TransportSettings, VERTEX_FIELDS, rename=VERTEX_PROPS),
            **properties(MaterialBakeSettings, MATERIAL_FIELDS, rename=MATERIAL_PROPS),
            **properties(ExportSettings, ("format", "godot"),
                         rename={"format": "export_format", "godot": "export_godot"},
                         defaults={"export_format": "rti-hsh"}),
            **properties(TransportTextureSettings, ("resolution",), defaults=_TRANSPORT,
                         update=_scale_with_resolution),
            **properties(TransportTextureSettings, ("bounces",), defaults=_LOBES),
            **properties(TransportTextureSettings, TRANSPORT_FIELDS, rename=TRANSPORT_PROPS,
                         defaults=_TRANSPORT)}


RelightSceneSettings.__annotations__.update(_declared_properties())


class RelightPreferences(bpy.types.AddonPreferences):
    """The add-on's preferences: what Run On Dask runs and which cluster it trusts. They live in
    Blender's user preferences, not in a .blend, so a received file cannot choose them
    (read through :func:`..farm.external_bake.farm_preferences`)."""

    bl_idname = ADDON_ID

    relight_command: StringProperty(
        name="Relight Command", subtype="FILE_PATH", default="",
        description="The `relight` console script of a Python environment with bpy and Dask "
                    "(e.g. <repository>/.venv/bin/relight), run by the panel's Run On Dask; "
                    "empty: `relight` on PATH")
    dask_scheduler: StringProperty(
        name="Dask Scheduler", default="",
        description="Address of a running Dask scheduler (e.g. tcp://host:8786) for Run On: "
                    "Dask Scheduler; its workers need this package and bpy, and read the .blend "
                    "and the output folder at the same paths. Trust: " + SCHEDULER_TRUST)

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "relight_command")
        col.prop(self, "dask_scheduler")
        col.label(text="A Dask scheduler can run code on this machine: connect only to a "
                       "cluster you trust", icon="ERROR")


CLASSES = (RelightSceneSettings, RelightPreferences)


def transport_settings_from_scene(props):
    """TransportTextureSettings from the panel's properties."""
    from ..bakes.texture_transport import TransportTextureSettings

    power = f":{props.horizon_power:g}" if props.horizon_power != 1.0 else ""
    given = values(TransportTextureSettings, props, ("resolution", "bounces") + TRANSPORT_FIELDS,
                   rename=TRANSPORT_PROPS)
    if getattr(props, "scene_bounces", False):
        given["bounces"] = -1          # the scene's Light Paths (texture_transport)
    # the scene's Sun: -1, resolved by the bake as the CLI's default is (its report says so)
    sun_angle = -1.0 if getattr(props, "scene_sun_size", False) else props.sun_angle
    return TransportTextureSettings(
        directions=f"hemi:{props.directions}{power}", sun_angle=sun_angle, **given)


def settings_from_scene(props):
    """TextureBakeSettings from the panel's properties."""
    from ..bakes.steerable_bake import TextureBakeSettings

    return TextureBakeSettings(**values(TextureBakeSettings, props, _SETTING_NAMES))


@bpy.app.handlers.persistent
def _on_depsgraph_update(scene, depsgraph):
    """Refresh the vertex preview when the chosen point lamp moves or changes power, and the
    texture previews lit by the World when the world changes (its image, strength, Mapping)."""
    props = getattr(scene, "relight", None)
    if props is None:
        return
    lamp = props.point_light
    watch_world = props.texture_light == "WORLD"
    if lamp is None and not watch_world:
        return                          # every depsgraph update passes here: nothing to watch
    lamp_moved = world_changed = False
    for update in depsgraph.updates:
        original = getattr(update.id, "original", None)
        if lamp is not None and original in (lamp, lamp.data):
            lamp_moved = True
        if watch_world and isinstance(update.id, bpy.types.World) and \
                update.id.original == scene.world:
            world_changed = True
    if lamp_moved:
        from ..preview.vertex_relight import update_preview

        update_preview(scene)
    if world_changed:
        from ..preview.transport_preview import update_environment_previews

        update_environment_previews(scene)


def register() -> None:
    bpy.types.Scene.relight = PointerProperty(type=RelightSceneSettings)
    # per object: a large receiver (the ground under a low sun's long shadows) at its own size
    bpy.types.Object.relight_resolution = IntProperty(
        name="Object Resolution", default=0, min=0, max=8192, soft_max=8192,
        description="This object's texture side in a transport bake (0: the Resolution above). "
                    "Objects of one side are baked together; every object still casts shadows "
                    "on the others")
    # the last failed bake's line, shown in the panel until the next bake (this session only:
    # not saved in the .blend, not undone)
    bpy.types.WindowManager.relight_last_failure = StringProperty(
        name="Last Failure", default="", options={"SKIP_SAVE"})
    bpy.app.handlers.depsgraph_update_post.append(_on_depsgraph_update)


def unregister() -> None:
    if _on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(_on_depsgraph_update)
    del bpy.types.Scene.relight
    del bpy.types.Object.relight_resolution
    del bpy.types.WindowManager.relight_last_failure

