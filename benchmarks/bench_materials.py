"""Benchmark (issue 14): material edits with precomputed transfer tensors (Sun et al. 2007).

1. Accuracy and cost of the bake on the sample ``room`` (all five meshes are receivers; the red
   and green walls are the editable regions), for each ``--settings`` entry
   ``DIRECT/ONE/TWO@SPP`` (direction specs of the three path orders; bounce terms by Cycles
   bakes at SPP samples) or ``DIRECT/ONE/TWO@rays:N`` (bounce terms gathered by N rays per
   receiver, the default bake): bake calls, seconds, bytes, and at held-out suns (``LIGHTS``:
   none is a baked direction) for several edits the relative error
   ``||E - E_cycles|| / ||E_cycles||`` (irradiance, vertices x RGB) against a Cycles bake of
   the same diffuse scene with the edit applied and 2 bounces, next to the noise floor (two
   truth seeds, ``--truth-spp``) and the error without the two-bounce term.
   Rows per setting: the sun's direct term from the bake's directions blended ("baked"), from
   a shadow ray per receiver ("rays", :mod:`relightable_textures.operators.base.direct_rays`) or
   rays only where the baked directions disagree ("rays-at-edges", the live preview); Cycles
   bounce terms as baked ("raw": no smoothing, two-bounce blended) or smoothed with the second
   bounce composed (:mod:`relightable_textures.lt_addon.transport.bounce_transfer`;
   "blended": smoothed, two-bounce blended); gathered ones with and without the receiver
   transfer that makes a sun's one-bounce light exact between the baked directions
   (:mod:`relightable_textures.lt_addon.transport.gathered_transfer`).
2. Update time on the room at ``--quads`` quads per wall side (default 56: 13,094 vertices, the
   paper's Table 1 has 13.0K) with 2 editable regions, baked for real with the default
   settings, timed over 50 updates each: material only, sun moved and material changed (rays
   at edges, the live preview; a ray to every receiver), environment rotated and material
   changed (the paper: 172 ms per update at 5.8 fps, 13K vertices), and a metallic edit with
   glossy anchors of the default shapes.

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


#: Quads per wall side of the room the update is timed on: 57 x 57 vertices on each of the
#: four planes and the demo's box, 13,094 vertices (the paper's Table 1 row has 13.0K).
TIMING_QUADS = 56


def update_timing(quads: int = TIMING_QUADS, repeats: int = 50,
                  settings: str = "hemi:400:1.5/hemi:128/hemi:8@rays:512") -> dict:
    """The room at ``quads`` quads per wall side, baked for real with ``settings`` (the
    default bake), then the live update timed over ``repeats`` updates each (median, ms):
    a material change alone; the Sun moved and a colour changed with rays where the baked
    directions disagree (the live preview) and with a ray to every receiver; the environment
    rotated and a colour changed; and with glossy anchors of the default shapes (random values:
    the cost does not depend on them) a metallic / roughness edit with the Sun moving."""
    import bpy

    from relightable_textures.lt_addon.transport import ptt
    from relightable_textures.operators.bakes import material_bake as mb
    from relightable_textures.operators.base.direct_rays import exact_direct
    from relightable_textures.operators.base.jobs import run
    from relightable_textures.samples import objects as sample_objects

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    sample_objects.build_room(scene, "demo", quads=quads)
    objs = [bpy.data.objects[n] for n in OBJECTS]
    t0 = time.perf_counter()
    t = run(mb.bake_materials(scene, objs, parse_setting(settings)))
    out = {"vertices": t.vertices, "regions": len(t.regions), "specs": list(t.specs),
           "bake_seconds": round(time.perf_counter() - t0, 1),
           "bake_calls": t.metadata["bake_calls"], "seconds": t.metadata["seconds"],
           "gather": t.metadata.get("gather"), "tensor_mib": round(t.nbytes / 2**20, 1),
           "receiver_transfer_mib": round(t.receiver_transfer.nbytes / 2**20, 1)
           if t.receiver_transfer is not None else None}
    rng = np.random.default_rng(0)
    env = rng.random((64, 128, 3))

    def timed(fn):
        fn(0)
        ts = []
        for i in range(repeats):
            a = time.perf_counter()
            fn(i)
            ts.append(time.perf_counter() - a)
        return round(1e3 * float(np.median(ts)), 3)

    def colours(i):
        return {"RedMaterial": (0.1 + 0.01 * (i % 50), 0.5, 0.5)}

    def moving_sun(i):
        a = np.radians(250.0 + 3.0 * i)
        return ptt.Sun((0.7 * np.cos(a), 0.7 * np.sin(a), 0.714))

    p = t.project(moving_sun(0), exact_direct(scene, t, moving_sun(0)))

    def material_only(i):
        c = t.albedos(colours(i))
        return t.receiver_colors(c) / np.pi * t.combine(p, c)

    def sun_and_material(i, everywhere=False):
        s = moving_sun(i)
        d = exact_direct(scene, t, s, everywhere=everywhere)
        return t.shade(s, colours(i), direct=d)

    def env_and_material(i):
        return t.shade(ptt.Environment(env, "bottom_first", 3.0 * i), colours(i))

    out["material_ms"] = timed(material_only)
    out["sun_rays_at_edges_and_material_ms"] = timed(sun_and_material)   # the live preview
    out["sun_rays_everywhere_and_material_ms"] = timed(lambda i: sun_and_material(i, True))
    out["environment_and_material_ms"] = timed(env_and_material)
    keep = t.receiver_transfer
    t.receiver_transfer = None
    out["sun_rays_at_edges_no_receiver_transfer_ms"] = timed(sun_and_material)
    t.receiver_transfer = keep
    def rays_only(i):
        exact_direct(scene, t, moving_sun(i), everywhere=False)

    out["rays_at_edges_ms"] = timed(rays_only)
    fixes = [t.project(moving_sun(i), exact_direct(scene, t, moving_sun(i))).fixed
             for i in range(0, 50, 5)]
    out["receivers_fixed_median"] = int(np.median(fixes))
    # glossy anchors (2 per region, at 128 directions), the red wall a metal whose roughness
    # changes while the Sun moves
    g = replace(t, roughness=(0.4, 0.8), gloss_spec="hemi:128",
                gloss=rng.random((128, len(t.regions), 2, t.vertices), dtype=np.float32))
    out["anchors_mib"] = round((g.nbytes - t.nbytes) / 2**20, 1)

    def sun_and_metal(i):
        s = moving_sun(i)
        return g.shade(s, colours(i), direct=exact_direct(scene, g, s, everywhere=False),
                       finish={"RedMaterial": (1.0, 0.4 + 0.008 * (i % 50))})

    out["sun_rays_at_edges_and_metal_ms"] = timed(sun_and_metal)
    return out


#: The demo's material bake (Makefile ``demo``), per face corner.
DEMO = "hemi:400:1.5/hemi:128/hemi:8@rays:512"


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
    from relightable_textures.operators.bakes import material_edit
    from relightable_textures.operators.base.jobs import run

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
    st = replace(parse_setting(entry or DEMO, anchors), domain="POINT" if entry else "CORNER")
    with tempfile.TemporaryDirectory() as tmp:
        out = run(material_edit.bake_job(scene, objs, st, tmp))
        cmp = material_edit.compare_edit(scene, out.tensors, {}, png, spp, finish=finish)
    cmp.update(bake_calls=out.report["bake_calls"],
               bake_seconds=out.report["timings"]["bake_seconds"])
    return cmp


def parse_setting(entry: str, anchors: str = "diffuse"):
    """``DIRECT/ONE/TWO@SPP`` (bounce terms by Cycles bakes at SPP samples) or
    ``DIRECT/ONE/TWO@rays:N`` (gathered by N rays per receiver) -> MaterialBakeSettings."""
    from relightable_textures.operators.bakes import material_bake as mb

    dirs, how = entry.split("@")
    kw = ({"bounce_bake": "rays", "rays": int(how.split(":")[1])} if how.startswith("rays")
          else {"bounce_bake": "cycles", "samples": int(how)})
    return mb.MaterialBakeSettings(regions=["RedMaterial", "GreenMaterial"],
                                   directions=tuple(dirs.split("/")), anchors=anchors, **kw)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="test", choices=("test", "demo"))
    ap.add_argument("--settings", default="hemi:400:1.5/hemi:128/hemi:8@rays:512,"
                    "hemi:400:1.5/hemi:128/hemi:8@16")
    ap.add_argument("--truth-spp", type=int, default=256)
    ap.add_argument("--quads", type=int, default=TIMING_QUADS,
                    help="quads per wall side of the room the update is timed on")
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

    print("update time (median of 50, ms):", update_timing(args.quads), flush=True)
    if args.no_bake:
        return
    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import ptt
    from relightable_textures.operators.bakes import material_bake as mb
    from relightable_textures.operators.base.direct_rays import exact_direct
    from relightable_textures.operators.base.jobs import run

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
        st = parse_setting(entry, args.anchors)
        dirs, how = entry.split("@")
        if st.gathers:   # the whole bake: the Cycles calls of the direct term, rays, tables
            t0 = time.perf_counter()
            smoothed = run(mb.bake_materials(scene, objs, st))
            secs = time.perf_counter() - t0
            print(f"bake {entry}: {secs:.1f} s; {smoothed.metadata['seconds']}; gather "
                  f"{smoothed.metadata['gather']}; {smoothed.metadata['bounce_transfer']}",
                  flush=True)
            # direct: rays (every receiver), rays-at-edges (the live preview) or baked (D
            # blended); the receiver transfer on (default) or off; second bounce composed
            rows = [(r, "composed", True) for r in ("rays", "rays-at-edges", None)] + [
                ("rays", "composed", False), ("rays", "blended", True)]
        else:
            t0 = time.perf_counter()
            raw = run(mb.bake_materials(scene, objs, replace(st, smoothing=0.0)))
            raw.bounce = None   # as baked: the Cycles time only, the fit's seconds taken out
            secs = (time.perf_counter() - t0
                    - raw.metadata.get("bounce_transfer", {}).get("seconds", 0.0))
            t0 = time.perf_counter()
            smoothed = run(mb.bounce_terms(scene, raw, st.smoothing))
            print(f"smoothing and second-bounce fit: {time.perf_counter() - t0:.2f} s; "
                  f"{smoothed.metadata['bounce_transfer']}", flush=True)
            rows = [(r, "raw", False) for r in (None, "rays")] + [("rays", "blended", False)] + [
                (r, "composed", False) for r in (None, "rays", "rays-at-edges")]
        for (rays, bounce, fix), (name, edit) in [(r, e) for r in rows for e in EDITS]:
            tensors, compose = (raw, False) if bounce == "raw" else (smoothed,
                                                                     bounce == "composed")
            keep = tensors.receiver_transfer
            if not fix:
                tensors.receiver_transfer = None
            errs, floors, lows, parts, fixed = [], [], [], [], []
            for li, (az, el) in enumerate(LIGHTS):
                a, b = truths[li, name]
                light = ptt.Sun(tuple(direction_from_az_el(az, el)))
                exact = exact_direct(scene, tensors, light, everywhere=rays == "rays") \
                    if rays else None
                p, c = tensors.project(light, exact, compose), tensors.albedos(edit)
                fixed.append(p.fixed)
                est, e0 = tensors.combine(p, c), tensors.combine(p, c, (0,))
                n = np.linalg.norm(a)
                parts.append((np.linalg.norm(e0 - direct[li]) / n,
                              np.linalg.norm((est - e0) - (a - direct[li])) / n))
                errs.append(rel(est, a))
                lows.append(rel(tensors.combine(p, c, (0, 1)), a))
                floors.append(rel(b, a))
            tensors.receiver_transfer = keep
            per = "/".join(f"{e:.3f}" for e in errs)
            label = (f"{dirs} @{how}, direct {rays or 'baked'}, bounces {bounce}"
                     + (", receiver transfer" if fix else (", no receiver transfer"
                                                           if st.gathers else "")))
            print(f"| {label} | "
                  f"{tensors.metadata['bake_calls']} | {secs:.1f} | "
                  f"{tensors.nbytes / 2**20:.2f} | {name} | {np.mean(errs):.4f} "
                  f"({np.mean(errs) / np.mean(floors):.2f}x; {per}) | "
                  f"{np.mean([p[0] for p in parts]):.4f} | {np.mean([p[1] for p in parts]):.4f} | "
                  f"{np.mean(floors):.4f} | {np.mean(lows):.4f} |"
                  + (f" fixed {int(np.median(fixed))}" if fix else ""), flush=True)
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
            print(f"| {dirs} @{how}, anchors {args.anchors}, rays, composed | "
                  f"{smoothed.metadata['bake_calls']} | {secs:.1f} | "
                  f"{smoothed.nbytes / 2**20:.2f} | {name} | {np.mean(errs):.4f} "
                  f"({np.mean(errs) / np.mean(floors):.2f}x; {per}) | "
                  f"as diffuse {np.mean(flat):.4f} | | {np.mean(floors):.4f} | "
                  f"{np.mean(lows):.4f} |", flush=True)


if __name__ == "__main__":
    main()
