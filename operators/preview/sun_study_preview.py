"""A sun study's maps on the objects in the viewport, in the false-colour ramp of its PNGs
(bpy; issue 58).

:func:`show` reads a ``relight sun-study`` folder (its ``sun_study.json`` and each object's
``<object>_sunlight_hours.exr`` or ``<object>_radiation.exr``; files from elsewhere: names
confined to the folder, sizes and contents checked, see :mod:`...lt_addon.io.untrusted`) and
puts a preview of kind :data:`KIND` on every object of the scene it names: the map divided by
the study's top value (its possible hours, or the largest radiation) through a Color Ramp of
the PNGs' viridis stops (:data:`...lt_addon.sun.study_images.RAMP`), texels the bake did not
fill in the PNGs' dark grey. Like every preview it shows in Material Preview only (EEVEE), is
switched by *Show Preview* and taken out by *Remove Preview*; a material other objects share is
copied. The panel draws the legend from the ramp node itself (:func:`legend`).
"""

from __future__ import annotations

import json

import bpy
import numpy as np

from ...lt_addon.io import exrio, untrusted
from ...lt_addon.sun import study_images
from ..base.meshes import baked_uv_name
from . import preview_nodes as pn

KIND = "sun_study"
#: What a map is, per choice: the file key in the study's report, the title, the unit.
MAPS = {"hours": ("hours_exr", "Hours of direct sun", "h"),
        "radiation": ("radiation_exr", "Solar radiation", "kWh/m2")}
#: Scene property: the map shown (JSON: folder, map, top, unit, objects), for the legend.
SHOWN_KEY = "relight_sun_study_shown"
_RAMP_LABEL = "Sun Study Legend"
#: on the ramp node: the value its right end stands for
_TOP = "relight_sun_study_top"
#: Largest map side read (a 8192^2 float map is 256 MiB).
MAX_SIDE = 8192


def _srgb_to_linear(c):
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _number(doc, *keys) -> float:
    """A finite number >= 0 at ``doc[k0][k1]...`` of an untrusted report, else 0."""
    for k in keys:
        doc = doc.get(k) if isinstance(doc, dict) else None
    ok = isinstance(doc, (int, float)) and not isinstance(doc, bool) and np.isfinite(doc)
    return float(doc) if ok and doc >= 0 else 0.0


def study_entries(folder: str, which: str = "hours"):
    """``([(object name, map path)], top, unit)`` of the study in ``folder``, from its report
    alone (untrusted input: the map names confined to the folder, fields type-checked; no map
    read yet). ``top`` is the scale's right end: the possible hours, or the largest radiation
    or the open ground's, whichever is more. ValueError / UntrustedFileError in one line when
    it is not a study or lacks the map."""
    if which not in MAPS:
        raise ValueError(f"map must be one of {sorted(MAPS)}, got {which!r}")
    key = MAPS[which][0]
    from ...lt_addon.sun.sun_study import KIND as STUDY_KIND, REPORT_NAME

    path = untrusted.confined(folder, REPORT_NAME, must_exist=True, folder=False)
    rep = untrusted.read_json(path)
    if rep.get("kind") != STUDY_KIND:
        raise ValueError(f"{path} is not a sun study's report (kind {rep.get('kind')!r})")
    entries, top = [], 0.0
    for entry in untrusted.field(rep, "objects", path, list):
        name = untrusted.field(entry, "object", path, str)
        files = untrusted.field(entry, "files", path, dict)
        if key not in files:
            raise ValueError(f"{path}: {name}: no {which} map (run sun-study with "
                             f"{'--radiation' if which == 'radiation' else 'its defaults'})")
        entries.append((name, untrusted.confined(folder, files[key], must_exist=True,
                                                  folder=False)))
        top = max(top, _number(entry, "hours", "possible_h") if which == "hours" else
                  max(_number(entry, "radiation", "max_kwh_m2"),
                      _number(entry, "radiation", "horizontal_kwh_m2", "total")))
    return entries, (top if top > 0.0 else 1.0), MAPS[which][2]


def read_map(exr: str):
    """``(values (R, R) float32, covered (R, R) bool)`` of one study map (untrusted: a
    regular file of capped size, a square of at most :data:`MAX_SIDE`, finite values >= 0)."""
    untrusted.regular_file(exr, 4 * MAX_SIDE * MAX_SIDE * 3 + 2**20)
    ch, _ = exrio.read_exr(exr)
    if "Y" not in ch or "A" not in ch:
        raise ValueError(f"{exr}: not a sun-study map (channels Y and A expected)")
    values, alpha = np.asarray(ch["Y"], np.float32), np.asarray(ch["A"], np.float32)
    if values.ndim != 2 or values.shape[0] != values.shape[1] or \
            values.shape != alpha.shape or values.shape[0] > MAX_SIDE:
        raise ValueError(f"{exr}: a map is square, up to {MAX_SIDE}^2; got {values.shape}")
    if not (np.all(np.isfinite(values)) and values.min() >= 0.0):
        raise ValueError(f"{exr}: values must be finite and >= 0")
    return values, alpha > 0.5


def _build(b, image, uv_map: str, top: float):
    """UV -> map / top -> viridis ramp, dark grey where no texel: the colour socket."""
    uv = b.node("ShaderNodeUVMap", -200, 700, label="Baked UV")
    uv.uv_map = uv_map
    tex = b.node("ShaderNodeTexImage", 0, 700, image=image, label="Sun study map")
    tex.interpolation = "Closest"
    b.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    ramp = b.node("ShaderNodeValToRGB", 300, 700, label=_RAMP_LABEL)
    elements = ramp.color_ramp.elements
    stops = np.linspace(0.0, 1.0, len(study_images.RAMP))
    lin = _srgb_to_linear(study_images.RAMP)
    while len(elements) > 2:
        elements.remove(elements[1])
    elements[0].position, elements[-1].position = 0.0, 1.0
    elements[0].color = (*map(float, lin[0]), 1.0)
    elements[-1].color = (*map(float, lin[-1]), 1.0)
    # a new element is put in place by its position (setting one later re-sorts the list)
    for pos, col in zip(stops[1:-1], lin[1:-1]):
        elements.new(float(pos)).color = (*map(float, col), 1.0)
    ramp[_TOP] = float(top)
    b.links.new(tex.outputs["Color"], ramp.inputs["Fac"])
    grey = b.node("ShaderNodeRGB", 300, 950, label="No texel")
    grey.outputs[0].default_value = (*map(float, _srgb_to_linear(study_images.UNCOVERED)), 1.0)
    mix = b.node("ShaderNodeMix", 600, 800, data_type="RGBA", label="Covered texels")
    socket = {s.identifier: s for s in mix.inputs}
    b.links.new(tex.outputs["Alpha"], socket["Factor_Float"])
    b.links.new(grey.outputs[0], socket["A_Color"])
    b.links.new(ramp.outputs["Color"], socket["B_Color"])
    return next(s for s in mix.outputs if s.identifier == "Result_Color")


def show(scene, folder: str, which: str = "hours") -> dict:
    """Put the study's ``which`` map on every mesh of ``scene`` it names (module docstring);
    returns ``{"objects": [...], "not_in_scene": [...], "top", "unit"}``."""
    entries, top, unit = study_entries(folder, which)
    shown, missing = [], []
    for name, exr in entries:
        obj = scene.objects.get(name)
        if name in shown:
            continue
        if obj is None or obj.type != "MESH":
            missing.append(name)
            continue
        # one map at a time, and only for the scene's own meshes: a report naming many
        # objects cannot make this read more maps than the scene has meshes
        values, covered = read_map(exr)
        R = values.shape[0]
        img_name = f"{name} sun study {which}"
        image = bpy.data.images.get(img_name)
        if image is None or not image.get(pn._TAG) or tuple(image.size) != (R, R):
            if image is not None and image.get(pn._TAG):     # ours, of another size
                bpy.data.images.remove(image)
            image = bpy.data.images.new(img_name, R, R, alpha=True, float_buffer=True)
        image.colorspace_settings.name = "Non-Color"
        rgba = np.empty((R, R, 4), np.float32)
        rgba[..., :3] = np.clip(values / top, 0.0, 1.0)[..., None]
        rgba[..., 3] = covered
        image.pixels.foreach_set(rgba.ravel())
        image.pack()
        image[pn._TAG] = True
        uv_map = baked_uv_name(obj)
        pn._wire_preview(obj, lambda b, i=image, m=uv_map, t=top: _build(b, i, m, t), KIND)
        shown.append(name)
    if not shown:
        raise ValueError("none of the study's objects (" + ", ".join(n for n, _ in entries[:8])
                         + f") is a mesh of scene {scene.name!r}")
    info = {"folder": folder, "map": which, "title": MAPS[which][1], "top": top,
            "unit": unit, "objects": shown, "not_in_scene": missing}
    scene[SHOWN_KEY] = json.dumps(info)
    return info


def legend(scene):
    """``(ramp node, info)`` of the map the scene shows, for the panel's legend; None when no
    material holds one."""
    text = scene.get(SHOWN_KEY)
    if not text:
        return None
    for mat in bpy.data.materials:
        tree = mat.node_tree
        if tree is None:
            continue
        for node in tree.nodes:
            if node.get(pn._TAG) and node.get("relight_preview_kind") == KIND and \
                    node.bl_idname == "ShaderNodeValToRGB":
                try:
                    return node, json.loads(text)
                except ValueError:
                    return None
    return None
