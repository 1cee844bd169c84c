"""Benchmark (issue 14): material edits with precomputed transfer tensors (Sun et al. 2007).

1. Accuracy and cost of the bake on the sample ``room`` (all five meshes are receivers; the red
   and green walls are the editable regions), for each ``--settings`` entry
   ``DIRECT/ONE/TWO@SPP`` (direction specs of the three path orders, samples of the bounce
   terms): bake calls, seconds, bytes, and at held-out suns (``LIGHTS``: none is a baked
   direction) for several edits the relative error ``||E - E_cycles|| / ||E_cycles||``
   (irradiance, vertices x RGB) against a Cycles bake of the same diffuse scene with the edit
   applied and 2 bounces, next to the noise floor (two truth seeds, ``--truth-spp``) and the
   error without the two-bounce term.
   Rows per setting: the sun's direct term from the bake's directions blended ("baked"), from
   a shadow ray per receiver ("rays", :mod:`relightable_textures.operators.direct_rays`) or
   rays only where the baked directions disagree ("rays-at-edges"); the bounce terms as baked
   ("raw": no smoothing, two-bounce blended) or smoothed with the second bounce composed
   (the default, :mod:`relightable_textures.lt_addon.transport.bounce_transfer`; "blended":
   smoothed, two-bounce blended).
2. Update time at ``--vertices`` (default 13,000) with 2 editable regions: tensors of the
   default shapes filled with random numbers (the cost does not depend on the values),
   timed over 50 updates each: material only, sun moved and material changed, environment
   rotated and material changed (the paper: 172 ms per update at 5.8 fps, 13K vertices),
   the second bounce composed as the default bake does (32 patches per region);
   and the rays: a floor grid of that many vertices under a box, one ray per lit vertex.

3. With ``--anchors roughness:R1,...``: every setting is baked with those glossy anchors too,
   and ``METAL_EDITS`` (a wall made a Principled metal) are compared the same way against
   Cycles bakes with the metal (2 bounces, glossy ones included), next to the error of
   taking the metal wall as diffuse (what a bake without anchors can do).

4. ``--metal-picture PNG``: the demo's bake (``DEMO``, or ``--picture-settings`` per vertex)
   with ``--anchors`` on a copy of the room whose red wall is a Principled BSDF, and the
   preview before and after making that wall a metal of roughness 0.5 next to Cycles renders
   of the same at ``--truth-spp`` (``material_edit.compare_edit``).

Usage: python benchmarks/bench_materials.py [--size test|demo]
           [--settings hemi:400:1.5/hemi:128/hemi:8@16,...] [--truth-spp 256] [--no-bake]
           [--anchors roughness:0.4,0.8] [--metal-picture PNG]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

LIGHTS = ((30.0, 45.0), (200.0, 30.0), (120.0, 65.0), (300.0, 20.0), (200.0, 15.0),
          (75.0, 10.0), (250.0, 45.0))
EDITS = (("file colours", {}),
         ("red wall blue", {"RedMaterial": (0.1, 0.1, 0.8)}),
         ("both walls white 0.8", {"RedMaterial": (0.8, 0.8, 0.8),
                                   "GreenMaterial": (0.8, 0.8, 0.8)}))
OBJECTS = ("Floor", "WallLeft", "WallRight", "WallBack", "Box")
#: Edits of the metallic / roughness (``--anchors``): name, colours, {material: (m, rho)}.
METAL_EDITS = (("red wall metal, roughness 0.4", {}, {"RedMaterial": (1.0, 0.4)}),
               ("red wall metal, roughness 0.6", {}, {"RedMaterial": (1.0, 0.6)}),
               ("red wall blue metal, roughness 0.8", {"RedMaterial": (0.1, 0.1, 0.8)},
                {"RedMaterial": (1.0, 0.8)}),
               ("both walls white 0.8 metal, roughness 0.5",
                {"RedMaterial": (0.8, 0.8, 0.8), "GreenMaterial": (0.8, 0.8, 0.8)},
                {"RedMaterial": (1.0, 0.5), "GreenMaterial": (1.0, 0.5)}),
               ("red wall half metal, roughness 0.6", {}, {"RedMaterial": (0.5, 0.6)}))


def update_timing(vertices: int, specs=("hemi:400:1.5", "hemi:128", "hemi:8"), regions: int = 2,
                  repeats: int = 50) -> dict:
    from relightable_textures.lt_addon.transport import ptt
    from relightable_textures.lt_addon.transport.texture import parse_directions

    rng = np.random.default_rng(0)
    S = [parse_directions(s).size for s in specs]
    R1 = regions + 1
    grid = _rays_receivers(vertices)   # a floor grid under a box: real shadows for the rays
    if grid is not None:
        vertices = grid["rays"].count
    t = ptt.TransferTensors(
        rng.random((S[0], vertices), dtype=np.float32),
        rng.random((S[1], 3, R1, vertices), dtype=np.float32),
        rng.random((S[2], 3, R1, R1, vertices), dtype=np.float32), specs,
        [f"R{i}" for i in range(regions)], np.full((regions, 3), 0.5),
        rng.integers(0, R1, vertices).astype(np.int16),
        rng.random((vertices, 3), dtype=np.float32), [("synthetic", vertices)])
    # the default bake's second-bounce composition: 32 patches per region
    from relightable_textures.lt_addon.transport.bounce_transfer import BounceTransfer

    owner = np.repeat(np.arange(R1), 32).astype(np.int16)
    t.bounce = BounceTransfer(rng.integers(0, len(owner), vertices).astype(np.int32), owner,
                              rng.random((len(owner), vertices), dtype=np.float32),
                              np.ones((vertices, 3), np.float32), np.ones((R1, R1)))
    env = rng.random((64, 128, 3))
    out = {"vertices": vertices, "regions": regions, "specs": list(specs),
           "tensor_mib": round(t.nbytes / 2**20, 1)}
    sun = ptt.Sun((0.3, 0.2, 0.93))
    p = t.project(sun)

    def timed(fn):
        fn(0)
        ts = []
        for i in range(repeats):
            a = time.perf_counter()
            fn(i)
            ts.append(time.perf_counter() - a)
        return round(1e3 * float(np.median(ts)), 3)

    def colours(i):
        return {"R0": (0.1 + 0.01 * (i % 50), 0.5, 0.5)}

    def moving_sun(i):
        a = np.radians(3.0 * i)
        return ptt.Sun((0.4 * np.cos(a), 0.4 * np.sin(a), 0.92))

    def material_only(i):
        c = t.albedos(colours(i))
        return t.receiver_colors(c) / np.pi * t.combine(p, c)

    def sun_and_material(i):
        return t.shade(moving_sun(i), colours(i))

    def env_and_material(i):
        return t.shade(ptt.Environment(env, "bottom_first", 3.0 * i), colours(i))

    out["material_ms"] = timed(material_only)
    out["sun_and_material_ms"] = timed(sun_and_material)
    out["environment_and_material_ms"] = timed(env_and_material)
    if grid is None:
        return out
    # the sun's exact direct term: the grid's D is its own rays at the baked directions (equal
    # to Cycles' bake, tests/blender/test_materials.py); rays go where D's neighbours disagree
    from relightable_textures.lt_addon.transport.texture import sun_weights

    rays, d0 = grid["rays"], t.direction_sets()[0]
    a = time.perf_counter()
    t.direct[:] = np.stack([rays.direct(w) for w in d0.directions])
    out["rays_build_ms"] = grid["build_ms"]
    out["grid_D_seconds"] = round(time.perf_counter() - a, 2)
    cast = []

    def exact(i, everywhere=False):
        s = moving_sun(i)
        known = None
        if not everywhere:
            idx, _ = sun_weights(d0, s.direction)
            known = rays.known_from(t.direct[idx], d0.directions[idx])
        d = rays.direct(s.direction, known=known)
        cast.append((rays.cast, rays.ties))
        return s, d

    # cast: one ray per vertex (where it is not known); ties: corners next to a shadow edge
    # cast again from inside their faces (direct_rays: a shadow edge through a vertex)
    out["rays_everywhere_ms"] = timed(lambda i: exact(i, True))
    out["rays_everywhere_cast"], out["rays_everywhere_ties"] = (
        int(v) for v in np.median(cast, axis=0))
    cast.clear()
    out["rays_ms"] = timed(exact)
    out["rays_cast"], out["rays_ties"] = (int(v) for v in np.median(cast, axis=0))

    def sun_rays_and_material(i, everywhere=True):
        s, d = exact(i, everywhere)
        return t.shade(s, colours(i), direct=d)

    out["sun_rays_and_material_ms"] = timed(sun_rays_and_material)   # the default
    out["sun_rays_at_edges_and_material_ms"] = timed(lambda i: sun_rays_and_material(i, False))
    # glossy anchors (2 per region), the first region a metal whose roughness changes
    g = replace(t, roughness=(0.4, 0.8),
                gloss=rng.random((S[1], regions, 2, vertices), dtype=np.float32))
    out["anchors_mib"] = round(g.nbytes / 2**20, 1)

    def finish(i):
        return {"R0": (1.0, 0.4 + 0.008 * (i % 50))}

    pg = g.project(sun)

    def metal_only(i):
        c, w = g.albedos(colours(i)), g.anchor_weights(finish(i))
        return g.receiver_colors(c, w) / np.pi * g.combine(pg, c, anchors=w)

    def sun_rays_at_edges_and_metal(i):
        s, d = exact(i, False)
        return g.shade(s, colours(i), direct=d, finish=finish(i))

    def sun_rays_at_edges_no_metal(i):   # metallic 0: the anchors are not projected
        s, d = exact(i, False)
        return g.shade(s, colours(i), direct=d)

    out["metal_and_colour_ms"] = timed(metal_only)
    out["sun_rays_at_edges_and_metal_ms"] = timed(sun_rays_at_edges_and_metal)
    out["sun_rays_at_edges_no_metal_ms"] = timed(sun_rays_at_edges_no_metal)
    return out


def _rays_receivers(vertices: int):
    """A floor grid of about ``vertices`` vertices under a box (bpy), as ReceiverRays, with the
    milliseconds its BVH and arrays took; None without bpy."""
    try:
        import bpy
    except ImportError:
        return None
    from relightable_textures.operators.direct_rays import ReceiverRays

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    n = int(round(np.sqrt(vertices))) - 1
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n, y_subdivisions=n, size=4.0)
    grid = bpy.context.active_object
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 0.8))
    a = time.perf_counter()
    rays = ReceiverRays(bpy.context.scene, [(grid.name, len(grid.data.vertices))], "POINT")
    return {"rays": rays, "build_ms": round(1e3 * (time.perf_counter() - a), 3)}


#: The demo's material bake (Makefile ``demo``): direction specs and samples, per face corner.
DEMO = (("hemi:256:1.5", "hemi:16", "hemi:4"), 32)


def metal_picture(png: str, size: str, anchors: str, finish: dict, spp: int,
                  entry: str | None = None, sun: tuple | None = None) -> dict:
    """Bake the room as the demo does with glossy ``anchors`` and render the preview of the
    ``finish`` edit (``{material: {"metallic": m, "roughness": r}}``) next to Cycles at
    ``spp`` samples (a metal's reflected sun is a caustic: 64 spp is mostly fireflies).
    ``entry`` ``DIRECT/ONE/TWO@SPP``: bake those settings per vertex instead; ``sun``
    ``(az, el)`` degrees: the scene's Sun lamp turned there first."""
    import tempfile

    import bpy

    from relightable_textures import samples
    from relightable_textures.operators import material_bake as mb
    from relightable_textures.operators import material_edit
    from relightable_textures.operators.jobs import run

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build("room", scene, size)
    from relightable_textures.samples.scene_setup import make_principled

    make_principled(bpy.data.materials["RedMaterial"])
    if sun is not None:
        from mathutils import Vector

        from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el

        d = Vector(direction_from_az_el(*sun))
        for lamp in (o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"):
            lamp.rotation_euler = (-d).to_track_quat("-Z", "Y").to_euler()
    objs = [bpy.data.objects[n] for n in OBJECTS]
    dirs, bake_spp, domain = DEMO[0], DEMO[1], "CORNER"
    if entry:
        dirs, bake_spp = entry.split("@")
        dirs, bake_spp, domain = tuple(dirs.split("/")), int(bake_spp), "POINT"
    st = mb.MaterialBakeSettings(regions=["RedMaterial", "GreenMaterial"], directions=dirs,
                                 samples=bake_spp, domain=domain, anchors=anchors)
    with tempfile.TemporaryDirectory() as tmp:
        out = run(material_edit.bake_job(scene, objs, st, tmp))
        cmp = material_edit.compare_edit(scene, out.tensors, {}, png, spp, finish=finish)
    cmp.update(bake_calls=out.report["bake_calls"],
               bake_seconds=out.report["timings"]["bake_seconds"])
    return cmp


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="test", choices=("test", "demo"))
    ap.add_argument("--settings", default="hemi:400:1.5/hemi:16/hemi:4@32,"
                    "hemi:400:1.5/hemi:64/hemi:8@32,hemi:400:1.5/hemi:128/hemi:8@16")
    ap.add_argument("--truth-spp", type=int, default=256)
    ap.add_argument("--vertices", type=int, default=13000)
    ap.add_argument("--no-bake", action="store_true", help="only the update timing")
    ap.add_argument("--anchors", default="diffuse",
                    help="glossy anchors of every setting's bake (and the metal edits)")
    ap.add_argument("--metal-picture", metavar="PNG",
                    help="only the picture of a metal edit (with --anchors, default 0.4,0.8)")
    ap.add_argument("--picture-sun", metavar="AZ,EL",
                    help="the picture's Sun (default: the scene's, 45 degrees up)")
    ap.add_argument("--picture-settings", metavar="DIRECT/ONE/TWO@SPP",
                    help="the picture's bake, per vertex (default: the demo's, per corner)")
    args = ap.parse_args(argv)
    if args.metal_picture:
        anchors = args.anchors if args.anchors != "diffuse" else "roughness:0.4,0.8"
        print(metal_picture(args.metal_picture, args.size, anchors,
                            {"RedMaterial": {"metallic": 1.0, "roughness": 0.5}},
                            args.truth_spp, args.picture_settings,
                            tuple(float(v) for v in args.picture_sun.split(","))
                            if args.picture_sun else None), flush=True)
        return

    print("update time (median of 50, ms):", update_timing(args.vertices), flush=True)
    if args.no_bake:
        return
    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import ptt
    from relightable_textures.operators import material_bake as mb
    from relightable_textures.operators.direct_rays import exact_direct
    from relightable_textures.operators.jobs import run

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build("room", scene, args.size)
    objs = [bpy.data.objects[n] for n in OBJECTS]
    V = sum(len(o.data.vertices) for o in objs)
    print(f"room ({args.size}): {V} vertices; regions RedMaterial, GreenMaterial", flush=True)

    # truths once per light and edit (two seeds), shared by every setting
    base = {"RedMaterial": (0.8, 0.1, 0.1), "GreenMaterial": (0.1, 0.8, 0.1)}
    truths, direct, t0 = {}, {}, time.perf_counter()
    for li, (az, el) in enumerate(LIGHTS):
        d = direction_from_az_el(az, el)
        direct[li] = mb.truth_irradiance(scene, objs, base, d, 0, 1)   # exact: hard sun, 1 spp
        for name, edit in EDITS:
            cols = {**base, **edit}
            truths[li, name] = [mb.truth_irradiance(scene, objs, cols, d, 2, args.truth_spp,
                                                    seed=s) for s in (1, 2)]
        for name, edit, finish in METAL_EDITS if args.anchors != "diffuse" else ():
            cols = {**base, **edit}
            truths[li, name] = [mb.truth_irradiance(scene, objs, cols, d, 2, args.truth_spp,
                                                    seed=s, finish=finish) for s in (1, 2)]
    print(f"truths: {len(truths) * 2} Cycles bakes at {args.truth_spp} spp in "
          f"{time.perf_counter() - t0:.1f} s", flush=True)

    def rel(x, y):
        return float(np.linalg.norm(x - y) / np.linalg.norm(y))

    print("err: relative error of E (mean over the lights, then per light); direct / indirect:"
          " the error of each part (truth's direct part: a 1-spp bounce-free bake, exact) over"
          " the norm of the whole truth")
    print("| setting | bake calls | bake s | MiB | edit | err | direct | indirect | "
          "noise floor | without two-bounce |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for entry in args.settings.split(","):
        dirs, spp = entry.split("@")
        st = mb.MaterialBakeSettings(regions=["RedMaterial", "GreenMaterial"],
                                     directions=tuple(dirs.split("/")), samples=int(spp),
                                     anchors=args.anchors)
        t0 = time.perf_counter()
        raw = run(mb.bake_materials(scene, objs, replace(st, smoothing=0.0)))
        raw.bounce = None   # as baked: the Cycles time only, the fit's seconds taken out
        secs = (time.perf_counter() - t0
                - raw.metadata.get("bounce_transfer", {}).get("seconds", 0.0))
        t0 = time.perf_counter()
        smoothed = run(mb.bounce_terms(scene, raw, st.smoothing))
        print(f"smoothing and second-bounce fit: {time.perf_counter() - t0:.2f} s; "
              f"{smoothed.metadata['bounce_transfer']}", flush=True)
        rows = [(r, "raw") for r in (None, "rays")] + [("rays", "blended")] + [
            (r, "composed") for r in (None, "rays", "rays-at-edges")]
        for (rays, bounce), (name, edit) in [(r, e) for r in rows for e in EDITS]:
            tensors, compose = (raw, False) if bounce == "raw" else (smoothed,
                                                                     bounce == "composed")
            errs, floors, lows, parts = [], [], [], []
            for li, (az, el) in enumerate(LIGHTS):
                a, b = truths[li, name]
                light = ptt.Sun(tuple(direction_from_az_el(az, el)))
                exact = exact_direct(scene, tensors, light, everywhere=rays == "rays") \
                    if rays else None
                p, c = tensors.project(light, exact, compose), tensors.albedos(edit)
                est, e0 = tensors.combine(p, c), tensors.combine(p, c, (0,))
                n = np.linalg.norm(a)
                parts.append((np.linalg.norm(e0 - direct[li]) / n,
                              np.linalg.norm((est - e0) - (a - direct[li])) / n))
                errs.append(rel(est, a))
                lows.append(rel(tensors.combine(p, c, (0, 1)), a))
                floors.append(rel(b, a))
            per = "/".join(f"{e:.3f}" for e in errs)
            print(f"| {dirs} @{spp} spp, direct {rays or 'baked'}, bounces {bounce} | "
                  f"{tensors.metadata['bake_calls']} | {secs:.1f} | "
                  f"{tensors.nbytes / 2**20:.2f} | {name} | {np.mean(errs):.4f} ({per}) | "
                  f"{np.mean([p[0] for p in parts]):.4f} | {np.mean([p[1] for p in parts]):.4f} | "
                  f"{np.mean(floors):.4f} | {np.mean(lows):.4f} |", flush=True)
        for name, edit, finish in METAL_EDITS if smoothed.roughness else ():
            errs, floors, lows, flat = [], [], [], []
            for li, (az, el) in enumerate(LIGHTS):
                a, b = truths[li, name]
                light = ptt.Sun(tuple(direction_from_az_el(az, el)))
                exact = exact_direct(scene, smoothed, light, everywhere=True)
                p = smoothed.project(light, exact)
                c, w = smoothed.albedos(edit), smoothed.anchor_weights(finish)
                errs.append(rel(smoothed.combine(p, c, anchors=w), a))
                lows.append(rel(smoothed.combine(p, c, (0, 1), w), a))
                flat.append(rel(smoothed.combine(p, c), a))    # the metal taken as diffuse
                floors.append(rel(b, a))
            per = "/".join(f"{e:.3f}" for e in errs)
            print(f"| {dirs} @{spp} spp, anchors {args.anchors}, rays, composed | "
                  f"{smoothed.metadata['bake_calls']} | {secs:.1f} | "
                  f"{smoothed.nbytes / 2**20:.2f} | {name} | {np.mean(errs):.4f} ({per}) | "
                  f"as diffuse {np.mean(flat):.4f} | | {np.mean(floors):.4f} | "
                  f"{np.mean(lows):.4f} |", flush=True)


if __name__ == "__main__":
    main()
