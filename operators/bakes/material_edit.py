"""Material edits in the viewport (bpy): the bake job, the live per-vertex preview and what
keeps it live (Sun et al. 2007's run time); the panel's operator is :mod:`..ui.material_ops`.

After ``bake-materials`` (CLI or the panel's *Bake Materials*), every receiver shows the
colour attribute :data:`ATTRIBUTE` -- outgoing diffuse radiance ``albedo / pi * E`` with the
editable materials' *current* colours and the scene's Sun lamp -- as emission. Changing an
editable material's Base Color (or moving the Sun) recomputes it in NumPy: a depsgraph handler
(:func:`on_depsgraph_update`) calls :func:`update_preview`, a few milliseconds at 13K vertices
(``benchmarks/bench_materials.py``). The Sun's direct light comes from shadow rays
(:mod:`.direct_rays`), not the baked directions blended: rays where the baked directions around
the Sun disagree, which keeps the update fast. The materials' own specular stays out
of the preview: it shows each receiver's diffuse part, so a metal (a bake with glossy anchors,
whose Metallic and Roughness re-shade the preview too) is black in it.
"""

from __future__ import annotations

import os
import time

import bpy
import numpy as np

from ...lt_addon.transport import ptt
from . import material_bake
from ..base.cycles_bake import BakeInputError
from ..base.meshes import set_color_attribute

ATTRIBUTE = "RelightMaterials"
#: Scene property: the last material bake's and update's summary (the panel shows it).
SUMMARY_KEY = "relight_material_summary"
_CACHE: dict = {}


def scene_bakes(scene) -> list:
    """``(first object, tensors)`` of every material bake recorded in ``scene`` (cached by file
    and modification time); bakes whose file is missing are skipped."""
    from ..base.blend_files import object_bakes

    out = []
    for obj in scene.objects:
        if obj.type != "MESH" or not any(b.get("kind") == material_bake.KIND
                                         for b in object_bakes(obj)):
            continue
        try:
            from ..base.blend_files import bake_file

            path = bake_file(obj, material_bake.KIND, "material")
        except (ValueError, FileNotFoundError):
            continue
        key = (obj.name, path, os.path.getmtime(path))
        if key not in _CACHE:
            for k in [k for k in _CACHE if k[0] == obj.name]:
                del _CACHE[k]
            _CACHE[key] = ptt.TransferTensors.load(path)
        out.append((obj, _CACHE[key]))
    return out


def preview_light(scene):
    """The light the preview shows: the panel's Sun lamp, else the scene's first Sun lamp
    (direction, angular size, strength, colour); None without one."""
    props = getattr(scene, "relight", None)
    lamp = props.sun if props is not None and props.sun is not None else None
    if lamp is None:
        suns = [o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"]
        lamp = min(suns, key=lambda o: o.hide_render) if suns else None
    if lamp is None:
        return None
    from mathutils import Vector

    d = (lamp.matrix_world.to_quaternion() @ Vector((0.0, 0.0, 1.0))).normalized()
    return ptt.Sun(tuple(d), float(np.degrees(lamp.data.angle)), float(lamp.data.energy),
                   tuple(lamp.data.color))


def update_preview(scene) -> dict:
    """Shade every material bake of ``scene`` with the current colours and Sun and write the
    receivers' :data:`ATTRIBUTE`; returns ``{"update_ms": ..., "write_ms": ...}`` (empty
    without a bake or a Sun)."""
    bakes = scene_bakes(scene)
    light = preview_light(scene) if bakes else None
    if light is None:
        return {}
    from ..base.direct_rays import exact_direct

    shade_ms = write_ms = 0.0
    for _, tensors in bakes:
        t0 = time.perf_counter()
        # rays only where the baked directions disagree: at 13K vertices the update took
        # 12-18 ms where a ray to every receiver took 27-30 ms (benchmarks/bench_materials.py)
        values = tensors.shade(light, material_bake.file_colours(tensors),
                               direct=exact_direct(scene, tensors, light, everywhere=False),
                               finish=material_bake.file_finish(tensors))
        t1 = time.perf_counter()
        domain = tensors.metadata.get("domain", "POINT")
        for name, rows in tensors.object_slices().items():
            obj = scene.objects.get(name)
            if (obj is None or obj.type != "MESH"
                    or material_bake.element_count(obj, domain) != rows.stop - rows.start):
                continue   # the mesh changed since the bake: leave it
            attrs = obj.data.color_attributes
            attr = attrs.get(ATTRIBUTE)
            if attr is not None and attr.domain != domain:
                attrs.remove(attr)
                attr = None
            attr = attr or attrs.new(ATTRIBUTE, "FLOAT_COLOR", domain)
            set_color_attribute(attr, values[rows])
            obj.data.update()
        shade_ms += 1e3 * (t1 - t0)
        write_ms += 1e3 * (time.perf_counter() - t1)
    return {"update_ms": round(shade_ms, 3), "write_ms": round(write_ms, 3)}


def install_preview(scene, tensors) -> None:
    """Wire :data:`ATTRIBUTE` into every receiver's materials and fill it."""
    from ..preview import preview_nodes

    update_preview(scene)
    for name, _ in tensors.objects:
        obj = scene.objects.get(name)
        if obj is not None and obj.type == "MESH":
            preview_nodes.install_attribute_preview(obj, ATTRIBUTE, kind=material_bake.KIND,
                                                    base_color=False, gated=True)


def bake_job(scene, objects, settings, out_dir: str, truth_samples: int = 0,
             preview: bool = True, resume: bool = True, client=None,
             blend_path: str | None = None):
    """``bake-materials`` as one job (:func:`.material_bake.materials_job`: chunk cache with
    ``resume``, Dask workers with ``client``), then the live preview on every receiver;
    returns the :class:`.material_bake.MaterialsBakeOutput`."""
    out = yield from material_bake.materials_job(scene, objects, settings, out_dir,
                                                 truth_samples=truth_samples, resume=resume,
                                                 client=client, blend_path=blend_path)
    if preview:
        install_preview(scene, out.tensors)
    return out


def compare_edit(scene, tensors, edits: dict, out_png: str, samples: int = 64,
                 resolution: int = 256, finish: dict | None = None) -> dict:
    """Look at an edit the way a user does: render the preview before and after ``edits``
    (``{material: RGB}``; ``finish`` ``{material: {"metallic": m, "roughness": r}}`` with
    glossy anchors) and Cycles renders of the same scene with the same materials (diffuse, or
    diffuse plus a Principled metal), lit by the preview's Sun with the bake's bounces, from
    the scene camera, which sees only the diffuse part as the preview does; write a captioned
    2 x 3 PNG (preview | Cycles | |difference| x 4; before on top) and return the relative
    RMSE of each row over the receivers' pixels. The scene is restored afterwards."""
    import math
    import tempfile

    from mathutils import Vector

    from ...lt_addon.io.contact_sheet import linear_to_srgb8, write_png
    from ...lt_addon.io.label import labelled_grid
    from ..preview import preview_nodes
    from ..preview.compare_render import render_camera, saved_render_settings

    light = preview_light(scene)
    if scene.camera is None or light is None:
        raise BakeInputError("the comparison needs a scene camera and a Sun lamp")
    cyc = scene.cycles
    saved = [(cyc, k, getattr(cyc, k)) for k in ("max_bounces", "diffuse_bounces",
                                                  "glossy_bounces", "transmission_bounces",
                                                  "sample_clamp_direct", "sample_clamp_indirect")]
    res = (scene.render.resolution_x, scene.render.resolution_y,
           scene.render.resolution_percentage)
    world, render = scene.world, saved_render_settings(scene)
    hidden = [(o, o.hide_render) for o in scene.objects if o.type == "LIGHT"]
    sockets = {r: material_bake.material_colour_socket(bpy.data.materials[r])
               for r in tensors.regions}
    before = {r: tuple(s.default_value) for r, s in sockets.items() if s is not None}
    finish = dict(finish or {})
    knobs = {r: material_bake.finish_sockets(bpy.data.materials[r]) for r in finish}
    for r, props in finish.items():
        missing = sorted(set(props) - set(knobs[r]))
        if missing:
            raise BakeInputError(f"{r}: its {missing[0]} is not an unlinked input of a "
                                 "Principled BSDF, so the preview cannot show the edit")
    knobs_before = [(sock, sock.default_value) for props in knobs.values()
                    for sock in props.values()]
    data = bpy.data.lights.new("RelightEditSun", type="SUN")
    sun = bpy.data.objects.new("RelightEditSun", data)
    rows, errors = [], []
    try:
        f = int(resolution) / max(res[0], res[1])
        scene.render.resolution_x = max(1, round(res[0] * f))
        scene.render.resolution_y = max(1, round(res[1] * f))
        scene.render.resolution_percentage = 100
        scene.world = None
        for o, _ in hidden:
            o.hide_render = True
        cyc.max_bounces = cyc.diffuse_bounces = tensors.bounces
        cyc.glossy_bounces = cyc.transmission_bounces = 0
        # unclamped, as the bake's truths: a metal's caustic is what a clamp would cut
        cyc.sample_clamp_direct = cyc.sample_clamp_indirect = 0.0
        data.energy, data.angle = light.strength, math.radians(light.angle_deg)
        data.color = light.color
        sun.rotation_euler = (-Vector(light.direction)).to_track_quat("-Z", "Y").to_euler()
        with tempfile.TemporaryDirectory() as tmp:
            for label, edit in (("before", {}), ("after", edits)):
                for r, rgb in edit.items():
                    if sockets.get(r) is not None:
                        sockets[r].default_value = (*rgb, 1.0)
                if label == "after":
                    for r, props in finish.items():
                        for k, v in props.items():
                            knobs[r][k].default_value = float(v)
                update_preview(scene)
                bpy.context.view_layer.update()
                # Cycles sees the preview for this render only (its output targets EEVEE)
                undo = preview_nodes.render_previews(
                    [o for o in (scene.objects.get(n) for n, _ in tensors.objects) if o],
                    "CYCLES")
                try:
                    preview = render_camera(scene, os.path.join(tmp, f"p_{label}.exr"), 1)
                finally:
                    for f in undo:
                        f()
                colours = {**material_bake.file_colours(tensors), **edit}
                metal = {k: v for k, v in material_bake.file_finish(tensors).items() if v[0] > 0}
                cyc.glossy_bounces = tensors.bounces if metal else 0
                scene.collection.objects.link(sun)
                try:
                    with material_bake.GatedMaterials(scene, [], colours, camera_colour=True,
                                                      gloss=bool(metal)) as gates:
                        gates.set_gates("all", "all")
                        gates.set_finish(metal)
                        truth = render_camera(scene, os.path.join(tmp, f"t_{label}.exr"), samples)
                finally:
                    scene.collection.objects.unlink(sun)
                mask = preview.sum(-1) > 0
                err = float(np.linalg.norm((preview - truth)[mask])
                            / max(np.linalg.norm(truth[mask]), 1e-30))
                errors.append(err)
                what = "file colours" if label == "before" else "edited"
                rows.append([(linear_to_srgb8(preview[::-1]), f"preview, {what}"),
                             (linear_to_srgb8(truth[::-1]), f"Cycles {samples} spp"),
                             (linear_to_srgb8(4.0 * np.abs(preview - truth)[::-1]),
                              f"|diff| x4, rel {err:.3f}")])
        write_png(out_png, labelled_grid(rows))
    finally:
        for r, rgb in before.items():
            sockets[r].default_value = rgb
        for sock, v in knobs_before:
            sock.default_value = v
        bpy.data.objects.remove(sun)
        bpy.data.lights.remove(data)
        for o, h in hidden:
            o.hide_render = h
        for owner, k, v in saved:
            setattr(owner, k, v)
        scene.world = world
        scene.render.resolution_x, scene.render.resolution_y, \
            scene.render.resolution_percentage = res
        render()
        update_preview(scene)
    return {"png": os.path.abspath(out_png), "rel_rmse_before": errors[0],
            "rel_rmse_after": errors[1], "truth_samples": samples,
            "edits": {k: list(v) for k, v in edits.items()}, "finish": finish}


_busy = []


@bpy.app.handlers.persistent
def on_depsgraph_update(scene, depsgraph):
    """Re-shade when a material, node tree or Sun lamp changed and the scene has a material
    bake (our own attribute writes change meshes only, so they do not come back here)."""
    if _busy:
        return
    kinds = (bpy.types.Material, bpy.types.NodeTree, bpy.types.Light)
    hit = any(isinstance(u.id, kinds) or (isinstance(u.id, bpy.types.Object)
                                          and u.id.type == "LIGHT" and u.is_updated_transform)
              for u in depsgraph.updates)
    if not hit:
        return
    _busy.append(True)
    try:
        timings = update_preview(scene)
    finally:
        _busy.pop()
    if timings:
        scene[SUMMARY_KEY + "_update"] = f"Last update {timings['update_ms']:.1f} ms"


def shade_edits(scene, obj, sets, *, env=None, env_path: str | None = None, rotate: float = 0.0,
                sun=None, sun_angle: float = 0.0, strength: float = 1.0, color=(1.0, 1.0, 1.0),
                direct: str = "rays", compare_png: str | None = None,
                compare_samples: int = 64) -> tuple:
    """``relight-materials``' work: the material bake of ``obj`` (its first object) shaded with
    the edits ``sets`` (``(material, "color" | "metallic" | "roughness", value)`` rows) applied
    to the file's colours and finish, under the environment ``env`` (turned by ``rotate``
    degrees), a sun at ``sun`` (azimuth, elevation) of ``sun_angle`` degrees, or else the
    scene's Sun lamp, times ``strength``. A sun's direct light comes from rays (``direct``
    "rays": everywhere; "auto": where the baked directions disagree; "baked": not). With
    ``compare_png`` the edit is also rendered next to Cycles (:func:`compare_edit`), written
    atomically. Returns radiance (V, 3) float32, what was done, and warnings."""
    from ...lt_addon.errors import InputError
    from ...lt_addon.io import atomic
    from ...lt_addon.sphere.hemisphere import direction_from_az_el

    try:
        tensors = material_bake.load_tensors(scene, obj)
    except (FileNotFoundError, ValueError) as exc:
        raise InputError(str(exc)) from None
    edits = material_bake.file_colours(tensors)
    finish = material_bake.file_finish(tensors)
    finish_edits: dict = {}
    warnings = []
    for mat, prop, value in sets:
        if mat not in tensors.regions:
            raise InputError(f"{mat!r} is not an editable region of this bake (regions: "
                             f"{', '.join(tensors.regions)}); bake it with --region {mat}")
        if prop == "color":
            edits[mat] = value
            continue
        if not tensors.roughness:
            raise InputError(f"{mat}.{prop}: this bake has only the diffuse anchor; bake it "
                             "with --anchors roughness:R1,R2,... for metallic / roughness edits")
        m, rho = finish[mat]
        finish[mat] = (value, rho) if prop == "metallic" else (m, value)
        finish_edits.setdefault(mat, {})[prop] = value
        if prop not in material_bake.finish_sockets(bpy.data.materials.get(mat)):
            warnings.append(f"{mat}'s {prop} is not an unlinked input of a Principled BSDF: "
                            "shaded as asked, but the file's material cannot show it")
    if env is not None:
        light = ptt.Environment(env, "bottom_first", -rotate, strength)
        what = {"env": os.path.abspath(env_path) if env_path else "given", "rotate": rotate}
    elif sun is not None:
        light = ptt.Sun(tuple(direction_from_az_el(*sun)), sun_angle, strength, color)
        what = {"sun": list(sun), "sun_angle": sun_angle}
    else:
        lamp = material_bake.reference_sun(scene)
        if lamp is None:
            raise InputError("the scene has no Sun lamp: give --sun AZ,EL or --env HDR.exr")
        light = ptt.Sun(tuple(lamp[0]), lamp[1], lamp[2] * strength, color)
        what = {"sun": "the scene's Sun lamp", "sun_angle": lamp[1]}
    exact = None
    t = time.perf_counter()
    if isinstance(light, ptt.Sun) and direct != "baked":
        from ..base.direct_rays import exact_direct

        exact = exact_direct(scene, tensors, light, everywhere=direct == "rays")
    values = tensors.shade(light, edits, direct=exact, finish=finish).astype(np.float32)
    ms = (time.perf_counter() - t) * 1e3
    what["direct"] = direct if exact is not None else "baked"
    info = {"objects": [n for n, _ in tensors.objects], "vertices": int(len(values)), **what,
            "edits": {k: [float(x) for x in v] for k, v in edits.items()},
            "finish": {k: {"metallic": float(v[0]), "roughness": float(v[1])}
                       for k, v in finish.items()},
            "update_ms": round(ms, 3), "mean": [float(v) for v in values.mean(axis=0)]}
    if compare_png:
        changed = {m: rgb for m, prop, rgb in sets if prop == "color"}
        with atomic.atomic_path(compare_png) as tmp:
            info["compare"] = compare_edit(scene, tensors, changed, tmp, compare_samples,
                                           finish=finish_edits)
        info["compare"]["png"] = compare_png
    return values, info, warnings
