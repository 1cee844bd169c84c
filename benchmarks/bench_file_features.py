"""Benchmark (issue 59): the features real .blend files have, each baked and compared texel by
texel with Cycles' own DIFFUSE bake of the same Sun -- or refused / said in one line.

Every row builds a small scene (bpy primitives: a box or Suzanne on a 4 m ground), bakes the
named objects together with the draft preset (64 directions, ``--resolution``, gathered bounces),
relights each object from T under three held-out Suns (2 degrees) and compares it with Cycles'
DIFFUSE radiance bake of the same Sun (64 spp, the bake's bounces) over the texels Cycles
covers: relative RMSE, the worst of the three Suns. A row is "same as Cycles" when its error is
within 1.25x the plain box's (the same scene without the feature, same run). A bake that is
refused prints its one line; the warnings a bake prints are listed.

Usage: python benchmarks/bench_file_features.py [--resolution 64] [--json out/bench/features.json]

Another version's row ("before"): run it with that version first on the path, e.g.
``git archive REV | tar -x -C /tmp/old/relightable_textures`` and ``PYTHONPATH=/tmp/old``.
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time

import numpy as np

LIGHTS = ((37.0, 25.0), (161.0, 40.0), (283.0, 60.0))


def _scene():
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    return scene


def _material(name, rgb):
    from relightable_textures.samples.scene_setup import diffuse_material

    return diffuse_material(name, tuple(rgb))


def _ground(size=4.0, name="Ground"):
    import bpy

    bpy.ops.mesh.primitive_plane_add(size=size, location=(0, 0, 0))
    g = bpy.context.active_object
    g.name = name
    g.data.materials.append(_material(name + "Mat", (0.6, 0.6, 0.6)))
    return g


def _box(name="Box", location=(0, 0, 0.5), rgb=(0.7, 0.3, 0.2), size=1.0):
    import bpy

    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    b = bpy.context.active_object
    b.name = name
    b.data.materials.append(_material(name + "Mat", rgb))
    return b


def _suzanne(scale=(1, 1, 1)):
    import bpy

    bpy.ops.mesh.primitive_monkey_add(location=(0, 0, 0.8))
    s = bpy.context.active_object
    s.name = "Suzanne"
    s.scale = scale
    bpy.ops.object.shade_smooth()
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(island_margin=0.02)
    bpy.ops.object.mode_set(mode="OBJECT")
    s.data.materials.append(_material("SuzanneMat", (0.8, 0.8, 0.8)))
    return s


# -- the rows: (name, what it builds; returns the objects to bake)

def row_plain():
    return [_box(), _ground()]


def row_two_uv_maps():
    box, ground = _box(), _ground()
    mesh = box.data
    uv = np.empty(len(mesh.loops) * 2)
    mesh.uv_layers[0].data.foreach_get("uv", uv)
    light = mesh.uv_layers.new(name="Lightmap")   # the first map transposed
    light.data.foreach_set("uv", uv.reshape(-1, 2)[:, ::-1].astype(np.float32).ravel())
    mesh.uv_layers.active = light
    mesh.uv_layers[0].active_render = True
    return [box, ground]


def row_suzanne():
    return [_suzanne(), _ground()]


def row_suzanne_mirrored():
    return [_suzanne(scale=(-1, 1, 1)), _ground()]


def row_colliding_names(names=("a/b", "a_b")):
    a = _box(names[0], location=(-0.8, 0, 0.5), rgb=(0.8, 0.1, 0.1))
    b = _box(names[1], location=(0.8, 0, 0.5), rgb=(0.1, 0.1, 0.8))
    return [a, b, _ground()]


def row_two_boxes():
    return row_colliding_names(("Red", "Blue"))


def row_hidden_occluder_baked():
    box = _box()
    box.hide_render = True
    return [box, _ground()]


def row_hidden_occluder():
    box = _box()
    box.hide_render = True
    return [_ground()]


def row_not_diffuse_visible():
    box = _box()
    box.visible_diffuse = False
    return [_ground()]


def row_no_shadow():
    box = _box()
    box.visible_shadow = False
    return [_ground()]


def row_shadow_catcher():
    box, ground = _box(), _ground()
    ground.is_shadow_catcher = True
    return [box, ground]


def row_holdout():
    box = _box()
    box.is_holdout = True
    return [_ground()]


def row_overlapping_uvs():
    box, ground = _box(), _ground()
    mesh = box.data
    uv = np.tile(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32), (len(mesh.polygons), 1))
    mesh.uv_layers[0].data.foreach_set("uv", uv.ravel())   # every face on one square
    return [box, ground]


def row_array_copies():
    box, ground = _box(location=(-0.8, 0, 0.5)), _ground()
    mod = box.modifiers.new("Array", "ARRAY")   # two copies laid on the same UVs
    mod.count, mod.relative_offset_displace = 2, (1.6, 0, 0)
    return [box, ground]


ROWS = {"plain box": row_plain, "two UV maps (lightmap active)": row_two_uv_maps,
        "Suzanne": row_suzanne, "Suzanne mirrored (scale x -1)": row_suzanne_mirrored,
        "two boxes (Red, Blue)": row_two_boxes, "the same named a/b and a_b": row_colliding_names,
        "hidden from render and baked": row_hidden_occluder_baked,
        "hidden occluder": row_hidden_occluder, "visible_diffuse off": row_not_diffuse_visible,
        "visible_shadow off": row_no_shadow, "shadow-catcher ground": row_shadow_catcher,
        "holdout occluder": row_holdout, "overlapping UV islands": row_overlapping_uvs,
        "Array copies sharing UVs": row_array_copies}


def measure(build, resolution: int) -> dict:
    """Bake the row's objects together and compare each with Cycles (module docstring)."""
    try:
        from relightable_textures.lt_addon.caveats import report_warnings
    except ImportError:   # (a version from before the caveats were said: --before runs)
        def report_warnings(rep):
            return list(rep.get("warnings", []))
    from relightable_textures.lt_addon.errors import InputError
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import bundle
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from relightable_textures.operators.base.jobs import run

    scene = _scene()
    objs = build()
    s = tx.settings_from_preset("draft", directions="hemi:64", resolution=resolution,
                                indirect_resolution=resolution // 2, bounces=2, sun_angle=2.0)
    t0 = time.perf_counter()
    try:
        out = run(tx.bake_job(scene, objs, s, tempfile.mkdtemp(prefix="relight-feature-"),
                              truth=0, compare=False, preview=False))
    except InputError as exc:
        return {"refused": str(exc).splitlines()[0]}
    seconds = time.perf_counter() - t0
    rows = {"seconds": round(seconds, 2), "objects": {}, "warnings": []}
    loaded = []
    for rep in out.reports:
        rows["warnings"] += report_warnings(rep)
        loaded.append(tx.load_bake(rep["report"]))
    with EnvironmentBake(scene, objs, resolution, 64, s.bounces, (8, 16), mode="radiance",
                         seed=1, world_sampling="none") as session:
        errs = [[] for _ in objs]
        for az, el in LIGHTS:
            d = direction_from_az_el(az, el)
            truths = session.bake_sun_all(d, 1.0, s.sun_angle)
            for i, ((bake, store, _), truth) in enumerate(zip(loaded, truths)):
                got = bundle.relight(bake, store, d, s.sun_angle, 1.0, source="transport")
                m = truth.sum(-1) > 0
                den = float(np.linalg.norm(truth[m]))
                errs[i].append(float(np.linalg.norm(got[m] - truth[m]) / den) if den else math.nan)
    for (bake, store, _), obj, e in zip(loaded, objs, errs):
        rows["objects"][obj.name] = {"worst": round(max(e), 4), "errors": [round(x, 4) for x in e]}
        store.close()
    rows["uv_map"] = {r["object"]: r.get("uv_map") for r in out.reports}
    rows["same_files"] = len({r["files"]["transport"] for r in out.reports}) < len(out.reports)
    rows["files"] = sorted({r["files"]["transport"].rsplit("/", 1)[-1] for r in out.reports})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--rows", default=";".join(ROWS), help="row names, separated by ';'")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    out = {"date": time.strftime("%Y-%m-%d %H:%M"), "resolution": args.resolution, "rows": {}}
    for name in [r for r in args.rows.split(";") if r]:
        res = measure(ROWS[name], args.resolution)
        out["rows"][name] = res
        if "refused" in res:
            print(f"{name:32s} refused: {res['refused']}", flush=True)
            continue
        errs = ", ".join(f"{k} {v['worst']:.3f}" for k, v in res["objects"].items())
        print(f"{name:32s} {errs}  ({res['seconds']} s)" +
              "".join(f"\n{'':34s}warning: {w}" for w in res["warnings"]), flush=True)
    if args.json:
        import pathlib

        pathlib.Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        pathlib.Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
