"""The "Relight" tab in the 3D viewport sidebar (bpy)."""

from __future__ import annotations

import bpy

import os

from ..bakes.analyze import SUMMARY_KEY
from ..base import compat
from ..base.blend_files import object_bakes
from .properties import measured_line, preset_differences, preview_sun_angle, ui_label
from ..preview.preview_nodes import COLOR_SLIDER, SLIDERS


class _RelightTab:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Relight"


class _RelightSubPanel(_RelightTab):
    bl_parent_id = "VIEW3D_PT_relight"


#: What the panel calls each bake kind (the records' ``kind``).
KIND_LABELS = {"transport_texture": "Transport texture", "steerable_texture": "Steerable texture",
               "eigentransport": "Vertex transport", "material_tensors": "Material edits",
               "sun_study": "Sun study map"}


class VIEW3D_PT_relight(_RelightTab, bpy.types.Panel):
    """Relightable data of the active object"""

    bl_label = "Relightable Textures"

    def draw(self, context):
        layout = self.layout
        obj = context.active_object
        if obj is None:
            layout.label(text="Select a mesh object to relight", icon="INFO")
            return
        if obj.type != "MESH":
            layout.label(text=f"{obj.name} is a {obj.type.lower()}, not a mesh", icon="ERROR")
            layout.label(text="Relighting works on mesh objects only")
            return
        box = layout.box()
        box.label(text=obj.name, icon="MESH_DATA")
        mesh = obj.data
        box.label(text=f"{len(mesh.vertices)} vertices, {len(mesh.polygons)} faces")
        if not mesh.uv_layers:
            box.label(text="No UV map: texture bakes need one", icon="ERROR")
        bakes = object_bakes(obj)
        if not bakes:
            box.label(text="No relightable data yet")
        for bake in bakes:
            col = box.column(align=True)
            row = col.row()
            kind = bake.get("kind", "?")
            row.label(text=f"{KIND_LABELS.get(kind, kind)}: "
                           f"{os.path.basename(str(bake.get('path', '?')))}", icon="IMAGE_DATA")
            if kind in KIND_LABELS:
                row.operator("relight.show_preview", text="Show").kind = kind
            if "order" in bake:
                col.label(text=f"Order {bake['order']}, {bake['resolution']} px, "
                               f"{bake['samples']} samples, {bake['storage']} storage, "
                               f"{bake.get('bake_seconds', 0):.1f} s")


def draw_sun_size(col, scene) -> None:
    """*Scene's Sun* and the Sun Size it gives (the field itself when it is off)."""
    props = scene.relight
    col.prop(props, "scene_sun_size")
    if props.scene_sun_size:
        angle, where = preview_sun_angle(scene)
        col.label(text=f"Sun Size: {angle:g}\u00b0 ({where})")
    else:
        col.prop(props, "sun_angle")


def preset_lines(props) -> list:
    """The lines under Preset, as ``[(text, icon)]``: the fields that differ from what the
    preset was measured with (by their labels), or its measured cost and error for the Sun Size
    in use, or that it has no measured figures."""
    changed = preset_differences(props)
    if changed:
        names = [ui_label(props, n) for n in changed]
        shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        verb = "differs" if len(names) == 1 else "differ"
        return [(f"Custom: {shown} {verb} from {props.preset.capitalize()}", "MODIFIER"),
                ("(its measured figures do not apply)", "BLANK1")]
    line = measured_line(props.method, props.preset, preview_sun_angle(props.id_data)[0])
    if line is None:
        return [("This preset has no measured figures", "INFO")]
    return [(line, "INFO")]


def output_lines(props) -> list:
    """Where the next bake writes, as ``[(text, icon)]``, and whether the file is unsaved."""
    from .bake_ops import BakeInputError, _output_dir

    try:
        folder = _output_dir(props)
    except BakeInputError as exc:
        return [(str(exc), "ERROR")]
    home = os.path.expanduser("~")
    shown = ("~" + folder[len(home):]) if folder.startswith(home + os.sep) else folder
    lines = [(f"Bakes into {shown}", "FILE_FOLDER")]
    if not bpy.data.filepath and not props.output_dir.strip():
        lines.append(("Unsaved file: save it to bake next to it", "INFO"))
    return lines


def _last_failure(layout, context) -> None:
    wm = context.window_manager
    text = getattr(wm, "relight_last_failure", "")
    if text:
        box = layout.box()
        box.alert = True
        for i, part in enumerate(_wrap(text, 70)):
            box.label(text=part, icon="ERROR" if i == 0 else "BLANK1")


def _wrap(text: str, width: int) -> list:
    import textwrap

    return textwrap.wrap(text, width) or [text]


def _viewport_hint(layout, context) -> None:
    """Where the preview shows: a line (and the view's shading buttons) when this 3D view
    shows Solid or Wireframe, or Cycles' Rendered view, which do not show the preview."""
    space = context.space_data
    shading = getattr(space, "shading", None)
    if shading is None:
        return
    engine = context.scene.render.engine
    if shading.type in ("SOLID", "WIREFRAME"):
        text = "Solid view: the preview shows in Material Preview"
    elif shading.type == "RENDERED" and engine == "CYCLES":
        text = "Cycles' Rendered view shows your materials: the preview is in Material Preview"
    else:
        return
    layout.label(text=text, icon="INFO")
    layout.row().prop(shading, "type", expand=True)


#: The empty Output field's hint, where this Blender's UI has placeholders (4.1 and later).
_PLACEHOLDER = ({"placeholder": "Default: next to the .blend"}
                if "placeholder" in bpy.types.UILayout.bl_rna.functions["prop"].parameters
                else {})


class VIEW3D_PT_relight_bake(_RelightSubPanel, bpy.types.Panel):
    """Bake: the few settings a first bake needs; the rest is in Advanced"""

    bl_label = "Bake Relightable Texture"

    def draw(self, context):
        props = context.scene.relight
        layout = self.layout
        col = layout.column()
        col.prop(props, "preset")
        for text, icon in preset_lines(props):
            col.label(text=text, icon=icon)
        col.prop(props, "resolution")
        row = col.row(align=True)
        row.prop(props, "check_vs_cycles")
        if props.check_vs_cycles:
            row.prop(props, "truth_lights")
        col.prop(props, "output_dir", **_PLACEHOLDER)
        for text, icon in output_lines(props):
            col.label(text=text, icon=icon)
        if not bpy.data.filepath and not props.output_dir.strip():
            col.operator("wm.save_as_mainfile", text="Save .blend First", icon="FILE_TICK")
        meshes = [o for o in context.selected_objects if o.type == "MESH"]
        if len(meshes) > 1:
            sides = {o.relight_resolution or props.resolution for o in meshes}
            layout.label(text=f"{len(meshes)} selected meshes are baked together" +
                         (f" ({len(sides)} groups by resolution)" if len(sides) > 1 else ""),
                         icon="INFO")
        row = layout.row(align=True)
        row.operator("relight.estimate", icon="TIME")
        from .bake_ops import LAST_ESTIMATE_KEY

        for line in str(context.scene.get(LAST_ESTIMATE_KEY, "")).splitlines():
            layout.label(text=line, icon="TIME")
        layout.operator("relight.bake_textures", text="Bake", icon="RENDER_STILL")
        _last_failure(layout, context)
        _last_bake(layout, context.scene)
        row = layout.row(align=True)
        row.operator("relight.open_bake_folder", icon="FILE_FOLDER")
        row.operator("relight.open_comparison", icon="IMAGE_DATA")
        if context.scene.get("relight_azimuth") is not None:
            _viewport_hint(layout, context)
        _kept_chunks(layout, context, "texture")


class VIEW3D_PT_relight_bake_advanced(_RelightTab, bpy.types.Panel):
    """Every other bake setting: method, directions, light paths, model, viewport, device"""

    bl_label = "Advanced"
    bl_parent_id = "VIEW3D_PT_relight_bake"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        props = context.scene.relight
        layout = self.layout
        layout.prop(props, "method")
        col = layout.column(align=True)
        if props.method == "transport":
            for name in ("directions", "horizon_power", "sun_angle", "under_horizon",
                         "sun_path", "sun_path_step", "study", "transport_direct", "texel_sampling", "bounces", "transport_indirect",
                         "indirect_rays", "indirect_components", "indirect_samples",
                         "indirect_resolution", "transport_components", "transport_tol",
                         "transport_viewport", "horizon_azimuths", "horizon_resolution",
                         "gpu_budget", "table_size"):
                # the gather's rays and components only when it gathers; the steerable term's
                # samples also serve the gather's fallback (objects not baked, several sides)
                if (name in ("indirect_rays", "indirect_components")
                        and props.transport_indirect != "gather") or (
                        name.startswith("indirect_") and props.transport_indirect == "none"):
                    continue
                if name == "sun_angle":      # the scene's Sun's, unless turned off
                    draw_sun_size(col, context.scene)
                    continue
                if name == "bounces":        # the scene's own, unless turned off
                    col.prop(props, "scene_bounces")
                    if props.scene_bounces:
                        from ..base.scene_sun import scene_bounces

                        col.label(text=f"Bounces: {scene_bounces(context.scene)} (the scene's)")
                        continue
                col.prop(props, name)
            if props.transport_model != "pca":
                # only the PCA previews live: the others are the command line's (a file of an
                # older version may hold one; the menu sets it back)
                col.prop(props, "transport_model")
                col.label(text=f"{ui_label(props, 'transport_model')}: only PCA previews live "
                               "in the viewport", icon="ERROR")
            obj = context.active_object
            if obj is not None and obj.type == "MESH":   # e.g. the ground at its own size
                layout.prop(obj, "relight_resolution", text=f"{obj.name} Resolution")
        else:
            for name in ("frame", "order", "samples", "bounces", "storage", "mode",
                         "world_sampling"):
                col.prop(props, name)
        _run_on(layout, props)


def _last_bake(layout, scene):
    """The last texture bake's summary (cost, error vs Cycles, comparison image) and its
    report's warnings (overlapping UVs, a check past its tolerance, a fallback)."""
    from .bake_ops import LAST_BAKE_KEY, WARNING_PREFIX

    for line in str(scene.get(LAST_BAKE_KEY, "")).splitlines():
        warn = line.startswith(WARNING_PREFIX)
        for i, part in enumerate(_wrap(line, 80)):
            layout.label(text=part, icon=("ERROR" if warn else "INFO") if i == 0 else "BLANK1")


def run_on_lines(props) -> list:
    """The lines under Run On Dask, as ``[(text, icon)]``: the add-on's preferences' Relight
    Command and Dask Scheduler (read-only here: a .blend does not choose them), what trusting a
    scheduler means, and a legacy value this .blend carries, said to be ignored (also when the
    bake runs here)."""
    from ..farm import external_bake as eb

    lines = []
    if props.run_on != "HERE":
        prefs = eb.farm_preferences()
        lines.append((f"Relight Command: {prefs.relight_command or '`relight` on PATH'}",
                      "CONSOLE"))
        if props.run_on == "SCHEDULER":
            lines.append((f"Dask Scheduler: {prefs.scheduler or 'not set'}", "NETWORK_DRIVE"))
            lines.append(("Connecting trusts that cluster with running code here", "ERROR"))
        lines.append((f"Set in {eb.WHERE}", "PREFERENCES"))
    for name, what in (("dask_command", "Relight Command"), ("dask_scheduler", "Scheduler")):
        legacy = getattr(props, name, "").strip()
        if legacy:
            lines.append((f"This .blend's {what} {legacy!r} is ignored (set in Preferences)",
                          "ERROR"))
    return lines


def _run_on(layout, props):
    """Where the bake below runs: here, or on Dask through the Relight Command of the add-on's
    preferences (drawn read-only, with the button that shows them)."""
    from ..farm.external_bake import ADDON_ID

    col = layout.column(align=True)
    col.prop(props, "device")
    col.prop(props, "mix_devices")
    if props.device_used:
        col.label(text=f"Baked On: {props.device_used}", icon="INFO")
    col.prop(props, "run_on")
    if props.run_on == "WORKERS":
        col.prop(props, "dask_workers")
    for text, icon in run_on_lines(props):
        col.label(text=text, icon=icon)
    if props.run_on != "HERE":
        col.operator("preferences.addon_show", text="Open Preferences",
                     icon="PREFERENCES").module = ADDON_ID


def _kept_chunks(layout, context, kind: str):
    """What a cancelled bake (``kind`` "texture", "vertex" or "materials") kept for the next
    one, and the button that discards it."""
    from .bake_ops import kept_chunks

    kept = kept_chunks(context, kind)
    if kept:
        layout.label(text=f"{sum(n for _, n in kept)} chunks of a cancelled bake are kept: "
                          "Bake resumes from them", icon="RECOVER_LAST")
        layout.operator("relight.discard_chunks", icon="TRASH").kind = kind


def _eevee_render_hint(layout, scene) -> None:
    """What an EEVEE render (F12) shows while the preview is on (render_guard): the user's
    materials when the interface is locked during renders, else the preview, with the toggle."""
    if scene.render.use_lock_interface:
        layout.label(text="EEVEE renders (F12) use your own materials", icon="INFO")
        return
    box = layout.box()
    box.label(text="EEVEE renders (F12) show the preview unless the", icon="INFO")
    box.label(text="interface is locked while rendering (safe to swap materials):")
    box.prop(scene.render, "use_lock_interface", text="Lock Interface for Renders")


class VIEW3D_PT_relight_light(_RelightSubPanel, bpy.types.Panel):
    """The light of the live preview, and whether it shows"""

    bl_label = "Preview Light"

    def draw(self, context):
        scene = context.scene
        layout = self.layout
        if "relight_azimuth" not in scene:
            layout.label(text="Bake first: the sliders come with the preview")
            return
        props = scene.relight
        layout.prop(props, "show_preview")
        if not props.show_preview:
            layout.label(text="Showing your own materials", icon="HIDE_ON")
        _viewport_hint(layout, context)
        if props.show_preview and scene.render.engine == compat.EEVEE_ENGINE:
            _eevee_render_hint(layout, scene)
        if any(g.name.startswith("Relight Transport (") for g in bpy.data.node_groups):
            layout.row().prop(props, "texture_light", expand=True)
        if props.texture_light == "WORLD":
            col = layout.column(align=True)
            col.prop(props, "env_strength")
            col.prop(props, "env_rotation")
            warning = scene.get("relight_texture_env_warning")
            for line in (warning.split("; ") if warning else ()):
                layout.label(text=line, icon="ERROR")
            layout.label(text="World lights the transport-texture previews; steerable ones "
                              "follow the sliders", icon="INFO")
        col = layout.column(align=True)
        for key in SLIDERS:
            if key != "relight_follow_sun":
                col.prop(scene, f'["{key}"]', text=key.replace("relight_", "").capitalize())
        col.prop(scene, f'["{COLOR_SLIDER}"]', text="Color")
        draw_sun_size(layout.column(align=True), scene)
        row = layout.row(align=True)
        row.prop(scene.relight, "sun")
        follow = scene.get("relight_follow_sun", 0.0) > 0.5
        op = row.operator("relight.follow_sun", text="Stop" if follow else "Follow",
                          depress=follow)
        op.follow = not follow
        layout.operator("relight.remove_preview", icon="X")


class VIEW3D_PT_relight_vertex(_RelightSubPanel, bpy.types.Panel):
    """Per-vertex eigentransport preview"""

    bl_label = "Vertex Transport Preview"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        props = context.scene.relight
        col = self.layout.column(align=True)
        col.prop(props, "env_strength")
        col.prop(props, "env_rotation")
        col.prop(props, "point_light")
        col.prop(props, "show_clusters")
        warning = context.scene.get("relight_vertex_warning")
        if warning:
            for line in warning.split("; "):
                self.layout.label(text=line, icon="ERROR")
        col = self.layout.column(align=True)
        col.prop(props, "vertex_directions")
        col.prop(props, "vertex_bounces")
        if props.vertex_bounces == 0:
            col.prop(props, "vertex_direct")
        col.prop(props, "vertex_energy")
        _run_on(self.layout, props)
        self.layout.operator("relight.bake_transport", icon="RENDER_STILL")
        _kept_chunks(self.layout, context, "vertex")
        self.layout.operator("relight.analyze", icon="GRAPH")
        summary = context.scene.get(SUMMARY_KEY)
        if summary:
            self.layout.label(text=summary, icon="INFO")


class VIEW3D_PT_relight_materials(_RelightSubPanel, bpy.types.Panel):
    """Material edits with interreflection (precomputed transfer tensors, Sun 2007)"""

    bl_label = "Material Edits"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        from ..base.blend_files import object_bakes
        from ..bakes.material_bake import KIND, finish_sockets, material_colour_socket
        from ..bakes.material_edit import SUMMARY_KEY

        layout, props = self.layout, context.scene.relight
        meshes = [o for o in context.selected_objects if o.type == "MESH"]
        mats = sorted({s.material for o in meshes for s in o.material_slots if s.material},
                      key=lambda m: m.name)
        if not mats:
            layout.label(text="Select the meshes that receive light")
        # metallic / roughness are editable where a bake has glossy anchors for the material
        # (from the bake records: drawing loads no file)
        glossy = {r for o in context.scene.objects if o.type == "MESH" for b in object_bakes(o)
                  if b.get("kind") == KIND and b.get("anchors", "diffuse") != "diffuse"
                  for r in b.get("regions", ())}
        col = layout.column(align=True)
        for mat in mats:
            row = col.row(align=True)
            row.prop(mat, "relight_editable", text=mat.name)
            socket = material_colour_socket(mat)
            if socket is not None:   # the material's own colour: edits show live after a bake
                row.prop(socket, "default_value", text="")
            if mat.name in glossy:
                knobs = finish_sockets(mat)
                if knobs:
                    row = col.row(align=True)
                    for k, sock in knobs.items():
                        row.prop(sock, "default_value", text=k.title())
        col = layout.column(align=True)
        col.prop(props, "material_bounces")
        col.prop(props, "material_direct")
        col.prop(props, "material_bounce_bake")
        col.prop(props, "material_rays" if props.material_bounce_bake == "rays"
                 else "material_samples")
        col.prop(props, "material_per_corner")
        col.prop(props, "material_directions")
        col.prop(props, "material_one_directions")
        if props.material_bounces >= 2:
            col.prop(props, "material_two_directions")
        col.prop(props, "material_anchors")
        if props.material_anchors.strip():
            col.prop(props, "material_anchor_directions")
            col.prop(props, "material_anchor_samples")
        if props.material_bounce_bake == "cycles" or props.material_anchors.strip():
            col.prop(props, "material_smoothing")
        _run_on(layout, props)
        layout.operator("relight.bake_materials", icon="RENDER_STILL")
        _kept_chunks(layout, context, "materials")
        for key in (SUMMARY_KEY, SUMMARY_KEY + "_update"):
            if context.scene.get(key):
                layout.label(text=context.scene[key], icon="INFO")


class VIEW3D_PT_relight_export(_RelightSubPanel, bpy.types.Panel):
    """Export a transport-texture bake: RTI planes with a web page, or a directional lightmap"""

    bl_label = "Export"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        from .export_ops import LAST_EXPORT_KEY

        layout, props = self.layout, context.scene.relight
        col = layout.column(align=True)
        col.prop(props, "export_format")
        if props.export_format == "rti-hsh":
            col.prop(props, "export_terms")
        if props.export_format == "godot-lightmap":
            col.prop(props, "export_godot")
        if props.export_format in ("sh-l1", "monosh", "godot-lightmap"):
            col.prop(props, "export_light")
            if props.export_light == "ENV":
                col.prop(props, "export_env")
                col.prop(props, "export_env_rotation")
        col.prop(props, "output_dir")
        col.prop(props, "export_force")
        layout.operator("relight.export", icon="EXPORT")
        layout.operator("relight.open_export_page", icon="URL")
        for line in context.scene.get(LAST_EXPORT_KEY, "").splitlines():
            layout.label(text=line, icon="INFO")


class VIEW3D_PT_relight_sun_study(_RelightSubPanel, bpy.types.Panel):
    """A relight sun-study folder's maps on the objects, with their legend"""

    bl_label = "Sun Study Map"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        from ..preview import sun_study_preview

        layout, props = self.layout, context.scene.relight
        col = layout.column(align=True)
        col.label(text=f"Place and dates: {props.study or 'fill Sun Study (Bake > Advanced)'}")
        row = col.row(align=True)
        row.prop(props, "sun_study_hours")
        row.prop(props, "sun_study_step")
        col.prop(props, "sun_study_radiation")
        col.prop(props, "sun_study_weather")
        col.operator("relight.run_sun_study", icon="PLAY")
        col = layout.column(align=True)
        col.prop(props, "sun_study_folder")
        col.row().prop(props, "sun_study_map", expand=True)
        layout.operator("relight.show_sun_study", icon="LIGHT_SUN")
        shown = sun_study_preview.legend(context.scene)
        if shown is None:
            layout.label(text="Make a study with relight sun-study (docs/sun-studies.md)")
            return
        ramp, info = shown
        box = layout.box()
        box.label(text=f"{info['title']}, {info['unit']}")
        box.template_color_ramp(ramp, "color_ramp", expand=False)
        row = box.row()
        top = float(info["top"])
        for f in (0.0, 0.25, 0.5, 0.75, 1.0):
            row.label(text=f"{f * top:.4g}")
        box.label(text="Dark grey: no texel. Material Preview shows it", icon="INFO")


class VIEW3D_PT_relight_samples(_RelightSubPanel, bpy.types.Panel):
    """Add the paper sample scenes"""

    bl_label = "Sample Scenes"

    def draw(self, context):
        settings = context.scene.relight
        col = self.layout.column()
        col.prop(settings, "sample_name")
        col.prop(settings, "sample_size")
        op = col.operator("relight.add_sample_scene", icon="ADD")
        op.name = settings.sample_name
        op.size = settings.sample_size


CLASSES = (VIEW3D_PT_relight, VIEW3D_PT_relight_bake, VIEW3D_PT_relight_bake_advanced,
           VIEW3D_PT_relight_light, VIEW3D_PT_relight_samples, VIEW3D_PT_relight_vertex,
           VIEW3D_PT_relight_materials, VIEW3D_PT_relight_export, VIEW3D_PT_relight_sun_study)
