"""Benchmark: the transport bake's indirect light gathered by rays over T's directions, against
today's order-3 steerable indirect bake (issue 32: "measure whether a ray-gathered bounce over
the same directions beats the steerable indirect bake in error and in time").

One transport bake (the balanced preset, ``--model none``: T, the albedo and the steerable
indirect term) of a demo scene; then, from the same T, the gathered indirect
(:mod:`relightable_textures.lt_addon.transport.gathered_indirect`): ``--rays`` cosine-weighted
rays from each texel centre of the ``--indirect-resolution`` grid, one and ``--bounces`` bounces,
and its PCA over directions (``--components``). Every variant adds the same direct light from T
(offline, no viewport) and is compared with Cycles' radiance bakes of Sun lamps with the scene's
2 bounces (``--truth-samples``) at the bench's four held-out lights (2 and 10 degree Suns) and,
with ``--path``, at six points of an animated Sun's path at 5-10 degrees of elevation (2 degree
Sun; the bake then adds directions along the path, as ``bench_sun_path.py``). Prints relative
RMSE (lights combined as ``sqrt(mean(rel^2))``), the indirect term's own error (against the
truths minus Cycles' 0-bounce bakes of the same Suns) and the seconds of each stage.

Usage: python benchmarks/bench_indirect_gather.py [--scene bumps] [--resolution 256]
       [--rays 64] [--path] [--out out/bench]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def gathered_indirect(scene, result, RI: int, rays: int, bounces: int, seed: int = 1):
    """The gathered indirect term of a transport bake's objects: ({object index: (3, S, P_o)
    I}, {object index: (TexelSamples, albedo at its gather points (P_o, 3), its first and last
    stacked gather point, its margin operator)}, figures)."""
    import bpy

    from relightable_textures.lt_addon.rays import engine
    from relightable_textures.lt_addon.rays.texels import extend_margin
    from relightable_textures.lt_addon.transport import gathered_indirect as gi
    from relightable_textures.operators.bakes import indirect_gather

    objs = [bpy.data.objects[b.name] for b in result.objects]
    R = result.objects[0].store.resolution
    t0 = time.perf_counter()
    V, T, recv, UV, grids = indirect_gather.gather_points(scene, objs, RI)
    occ = engine.Occluder(V, T)
    gmaps, origins, normals, geo, offs = indirect_gather.stack_points(grids, RI)
    t_scene = time.perf_counter() - t0
    t0 = time.perf_counter()
    g = gi.gather(occ.nearest, origins, normals, geo, rays, seed, V, T, recv, UV, R,
                  [i * R * R for i in range(len(objs))], RI, gmaps)
    t_rays = time.perf_counter() - t0
    t0 = time.perf_counter()
    Tall = np.concatenate([np.asarray(b.store.array, np.float32) for b in result.objects], axis=1)
    alb = np.concatenate([b.albedo.reshape(-1, 3) for b in result.objects])
    t_read = time.perf_counter() - t0
    out, seconds = {}, {}
    for nb in sorted({1, bounces}):
        t0 = time.perf_counter()
        out[nb] = gi.indirect(g, Tall, alb, bounces=nb)
        seconds[f"bounces_{nb}"] = round(time.perf_counter() - t0, 2)
    del Tall
    centre = ((np.arange(RI) + 0.5) * R / RI).astype(np.int64)
    per = {}
    for i, (smp, _) in enumerate(grids):
        a = result.objects[i].albedo[centre][:, centre].reshape(-1, 3)[smp.texel]
        # the bake's Extend margin (4 texels at T's side), as every baked image has it
        margin = extend_margin(smp.covered(), max(1, -(-4 * RI // R)))
        per[i] = (smp, a, offs[i], offs[i + 1], margin)
    figures = {"scene_seconds": round(t_scene, 2), "ray_seconds": round(t_rays, 2),
               "read_T_seconds": round(t_read, 2), **seconds, **g.figures(),
               "rays": int(occ.rays)}
    return out, per, figures, (g, alb)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="bumps")
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--indirect-resolution", type=int, default=128)
    ap.add_argument("--rays", type=int, default=64)
    ap.add_argument("--bounces", type=int, default=2)
    ap.add_argument("--components", type=int, default=16)
    ap.add_argument("--truth-samples", type=int, default=256)
    ap.add_argument("--path", action="store_true",
                    help="also a Sun animated over a day: six lights on its path at 5-10 deg")
    ap.add_argument("--out", default="out/bench")
    args = ap.parse_args(argv)

    import bench_transport_textures as btt

    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import texture as tt
    from relightable_textures.lt_addon.transport.bundle import rel_rmse, upsample
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.bakes.indirect_gather import StackedRows
    from relightable_textures.operators.base.jobs import run

    R, RI = args.resolution, args.indirect_resolution
    report = {"date": time.strftime("%Y-%m-%d %H:%M"), "scene": args.scene, "resolution": R,
              "indirect_resolution": RI, "rays": args.rays, "bounces": args.bounces,
              "truth_samples": args.truth_samples, "cases": []}
    cases = [("held-out", None)] + ([("sun path", "path")] if args.path else [])
    for label, kind in cases:
        scene, objects = btt.build(args.scene, "demo")
        if kind == "path":
            sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(
                os.path.abspath(__file__))), "tests", "blender"))
            from test_sun_path import _animate_sun

            _animate_sun(scene)
            lights = []
            for el in (5.0, 7.5, 10.0):
                t = math.asin((el + 3) / 53) / math.pi
                lights += [((80 + 200 * t, el), 2.0), ((80 + 200 * (1 - t), el), 2.0)]
        else:
            lights = [(l, a) for a in btt.ANGLES for l in tx.TRUTH_LIGHTS]
        t0 = time.perf_counter()
        truth2, truth0 = {}, {}
        for angle in sorted({a for _, a in lights}):
            ls = [l for l, a in lights if a == angle]
            got2 = run(tx.truth_bakes(scene, objects, ls, angle, 2, args.truth_samples, R))
            got0 = run(tx.truth_bakes(scene, objects, ls, angle, 0, args.truth_samples, R))
            for l in ls:
                truth2[(l, angle)], truth0[(l, angle)] = got2[l], got0[l]
        truth_s = time.perf_counter() - t0
        single = btt.single_bake_seconds(scene, objects, R)
        print(f"{label}: truths {truth_s:.1f} s; one 64-spp bake {single:.2f} s", flush=True)
        folder = tempfile.mkdtemp()
        s = tx.settings_from_preset("balanced", resolution=R, model="none", indirect="steerable",
                                    **({"sun_path": "auto"} if kind == "path" else
                                       {"sun_path": "off"}))
        t0 = time.perf_counter()
        res = run(tx.bake_transport_textures(scene, objects, s, folder, resume=False))
        bake_s = time.perf_counter() - t0
        steer = {k: round(v, 2) for k, v in res.seconds.items()
                 if k in ("indirect_cycles", "indirect_total", "direct_total")}
        I, per, figs, (g, alb) = gathered_indirect(scene, res, RI, args.rays, args.bounces)
        # what a bake would do: the same PCA by a randomised SVD, I never formed, T read from
        # the stores in chunks (the gather's rays are the same, timed above)
        from relightable_textures.lt_addon.transport import gathered_indirect as gi

        t0 = time.perf_counter()
        Vr, Ur, _ = gi.indirect_pca(g, StackedRows([b.store.array for b in res.objects]), alb,
                                    bounces=args.bounces, components=args.components)
        figs["randomised_pca_seconds"] = round(time.perf_counter() - t0, 2)
        Ur = Ur.reshape(len(Ur), -1)
        # PCA over directions of the gathered term (all objects and colours): Gram, eigh
        t0 = time.perf_counter()
        full = I[args.bounces]
        S = full.shape[1]
        Y = full.transpose(1, 0, 2).reshape(S, -1).astype(np.float64)
        ev, Vec = np.linalg.eigh(Y @ Y.T)
        Vk = Vec[:, ::-1][:, :args.components]
        Uk = Vk.T @ Y
        figs["pca_seconds"] = round(time.perf_counter() - t0, 2)
        figs["pca_energy"] = round(float(ev[::-1][:args.components].sum() / ev.sum()), 5)
        del Y
        dset = res.objects[0].store.directions

        def gathered_image(oi, d, angle, which):
            idx, w = tt.sun_weights(dset, d, angle, "linear")
            smp, a, lo, hi, (dst, op) = per[oi]
            if which == "pca":
                v = ((w @ Vk[idx]) @ Uk).reshape(3, -1)[:, lo:hi].T
            elif which == "rpca":
                v = ((w @ Vr[idx]) @ Ur).reshape(3, -1)[:, lo:hi].T
            else:
                v = np.einsum("s,csp->pc", w, I[which][:, idx, lo:hi])
            img = np.zeros((RI * RI, 3), np.float32)
            img[smp.texel] = v * a
            if dst.size:
                img[dst] = op @ (v * a)
            return upsample(img.reshape(RI, RI, 3), R)

        variants = ("steerable", "gathered, 1 bounce", f"gathered, {args.bounces} bounces",
                    f"gathered, {args.bounces} bounces, PCA {args.components}",
                    f"gathered, {args.bounces} bounces, randomised PCA {args.components}")
        errs = {v: {} for v in variants}
        ind_errs = {v: {} for v in variants}
        for (l, angle) in lights:
            d = direction_from_az_el(*l)
            for oi, b in enumerate(res.objects):
                idx, w = tt.sun_weights(b.store.directions, d, angle, res.settings.kernel)
                direct = b.store.relight(idx, w)[..., None] * b.albedo
                t2, t0_ = truth2[(l, angle)][oi], truth0[(l, angle)][oi]
                imgs = {variants[0]: upsample(b.indirect.relight(np.asarray(d, np.float64)), R),
                        variants[1]: gathered_image(oi, d, angle, 1),
                        variants[2]: gathered_image(oi, d, angle, args.bounces),
                        variants[3]: gathered_image(oi, d, angle, "pca"),
                        variants[4]: gathered_image(oi, d, angle, "rpca")}
                for v, img in imgs.items():
                    errs[v].setdefault(angle, []).append(rel_rmse(direct + img, t2))
                    ind_errs[v].setdefault(angle, []).append(
                        float(np.linalg.norm(img - (t2 - t0_)) / np.linalg.norm(t2)))
        for b in res.objects:
            b.store.abort()
        rows = [{"indirect": v, **{f"err_{a:g}deg": round(btt.combined(e), 4)
                                   for a, e in errs[v].items()},
                 **{f"indirect_err_{a:g}deg": round(btt.combined(e), 4)
                    for a, e in ind_errs[v].items()}} for v in variants]
        case = {"case": label, "lights": [list(l) + [a] for l, a in lights],
                "directions": int(dset.size), "bake_seconds": round(bake_s, 1),
                "single_bake_seconds": round(single, 2), "steerable_seconds": steer,
                "gather": figs, "rows": rows}
        report["cases"].append(case)
        print(json.dumps(case), flush=True)
        del I
    for case in report["cases"]:
        angles = sorted({a for *_, a in case["lights"]})
        print(f"\n{case['case']} ({case['directions']} directions; one 64-spp bake "
              f"{case['single_bake_seconds']} s; steerable indirect "
              f"{case['steerable_seconds'].get('indirect_total')} s; gathered: rays "
              f"{case['gather']['ray_seconds']} s, bounces "
              f"{case['gather'].get('bounces_1')} / "
              f"{case['gather'].get(f'bounces_{args.bounces}')} s, PCA "
              f"{case['gather']['pca_seconds']} s; randomised PCA, I not formed: "
              f"{case['gather']['randomised_pca_seconds']} s)")
        print("| indirect | " + " | ".join(f"err {a:g}° | its indirect {a:g}°" for a in angles)
              + " |")
        print("|---|" + "---|---|" * len(angles))
        for r in case["rows"]:
            print(f"| {r['indirect']} | " + " | ".join(
                f"{r[f'err_{a:g}deg']:.4f} | {r[f'indirect_err_{a:g}deg']:.4f}" for a in angles)
                + " |")
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, f"indirect_gather_{args.scene}.json"), "w") as fh:
        json.dump(report, fh, indent=1)


if __name__ == "__main__":
    main()
