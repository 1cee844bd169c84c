"""The viewport representations at real texture sizes (issue 33): size, lookups per pixel and
error against Cycles for each, with the bake's wall time, memory and disk.

Per scene and resolution: one bake with the given preset's directions (rays), then for each
viewport representation that could show it -- T through sparse tables (its 8-bit atlas), the
block viewport chosen within ``--gpu-budget`` (:mod:`lt_addon.transport.block_viewport`), the
global PCA the bake fits -- its GPU memory (half-float RGBA, 8-bit for T's atlas), texture
lookups per pixel (direct light; the indirect term adds its 9), and the relative RMSE of what it
shows (through its own tables: :func:`lt_addon.transport.texture.table_weights`) against Cycles Sun-lamp radiance bakes with the scene's 2 bounces at the four held-out
lights (elevations 10, 30, 55, 80 degrees), for a 2- and a 10-degree Sun, ``sqrt(mean(rel^2))``
over lights and objects, plus the ground's figure at 10 degrees elevation. The bake's time is a
ratio to one 64-spp Cycles bake of the same textures measured in the same run.

Usage: python benchmarks/bench_viewports.py [--scenes statue,bumps] [--resolutions 512,1024]
           [--preset balanced] [--truth-samples 64] [--gpu-budget 512] [--size demo|test]
           [--indirect-resolution SIDE]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="statue,bumps")
    ap.add_argument("--resolutions", default="512,1024")
    ap.add_argument("--preset", default="balanced")
    ap.add_argument("--truth-samples", type=int, default=64)
    ap.add_argument("--gpu-budget", type=int, default=512)
    ap.add_argument("--size", default="demo", choices=("demo", "test"))
    ap.add_argument("--indirect-resolution", type=int, default=0,
                    help="the indirect grid's side (default: the preset's at that resolution, as "
                         "a user's bake of it gets; until 2026-12-04 it was R / 2)")
    args = ap.parse_args(argv)

    from bench_transport_textures import ANGLES, build, combined, single_bake_seconds, truths
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.lt_addon.transport import block_viewport as bv
    from relightable_textures.lt_addon.transport.bundle import HORIZON_LOOKUPS
    from relightable_textures.lt_addon.transport import sparse_tables as sp
    from relightable_textures.lt_addon.transport import texture as tt
    from relightable_textures.lt_addon.transport.gathered_texture import indirect_images
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.bakes.presets import TRANSPORT
    from relightable_textures.operators.base.jobs import run

    preset = TRANSPORT.settings(args.preset)
    print(f"Measured {time.strftime('%Y-%m-%d %H:%M')} on {os.cpu_count()} cores: {args.preset} "
          f"preset ({preset.directions}), truths {args.truth_samples} spp with 2 bounces, GPU "
          f"budget {args.gpu_budget} MiB per object\n")
    for name in args.scenes.split(","):
        for R in (int(r) for r in args.resolutions.split(",")):
            scene, objects = build(name, args.size)
            one = single_bake_seconds(scene, objects, R)
            truth = truths(scene, objects, R, args.truth_samples)
            from dataclasses import replace

            at_r = TRANSPORT.settings(args.preset, resolution=R)   # its grids scaled with R
            s = replace(at_r, bounces=2, model="pca",
                        indirect_resolution=(args.indirect_resolution
                                             or at_r.indirect_resolution),
                        viewport="auto", gpu_budget=args.gpu_budget)
            folder = tempfile.mkdtemp(prefix=f"bench-viewports-{name}-{R}-")
            t0 = time.perf_counter()
            result = run(tx.bake_transport_textures(scene, objects, s, folder, resume=False))
            bake_s = time.perf_counter() - t0
            stores = [b.store for b in result.objects]
            disk = sum(os.path.getsize(st.path) for st in stores)
            print(f"\n## {name} at {R}^2 ({', '.join(o.name for o in objects)})\n")
            print(f"bake {bake_s:.1f} s = {bake_s / one:.1f}x one 64-spp bake ({one:.1f} s); "
                  f"stages: " + ", ".join(f"{k} {v:.1f} s" for k, v in result.seconds.items()
                                          if k in ("direct_total", "indirect_total", "fit"))
                  + f"; peak RSS above start {result.peak_rss_mb:.0f} MB; T on disk "
                  f"{disk / 2**30:.2f} GiB; indirect grid {s.indirect_resolution}^2, horizons "
                  f"at {result.direct.get('horizon_resolution')}^2")
            for b in result.objects:
                print(f"  {b.name}: viewport {b.viewport.get('shows')} ({b.viewport.get('why')})"
                      + (f", block {b.viewport['block']} x {b.viewport['components']} comps, "
                         f"fit {b.viewport['fit_seconds']:.1f} s, tried "
                         f"{b.viewport['choice']['tried']}" if b.view is not None else ""))
            rows = {}

            def add(label, fn, mib, lookups):
                errs, ground = {}, None
                for a in ANGLES:
                    e = []
                    for az, el in tx.TRUTH_LIGHTS:
                        d = direction_from_az_el(az, el)
                        for oi, b in enumerate(result.objects):
                            img = fn(oi, d, a)
                            if b.indirect is not None:
                                img = img + tx._upsample(indirect_images(b.indirect, d, a), R)
                            r = tx.rel_rmse(img, truth[a][(az, el)][oi])
                            e.append(r)
                            if a == 10.0 and el == 10.0 and b.name == "Ground":
                                ground = r
                    errs[a] = combined(e)
                rows[label] = (errs, ground, mib, lookups)
                cell = f"{mib:.1f}" if isinstance(mib, (int, float)) else mib
                print(f"| {label} | {cell} | {lookups} | {errs[2.0]:.4f} | {errs[10.0]:.4f} | "
                      + (f"{ground:.4f}" if ground is not None else "-") + " |", flush=True)

            print("\n| viewport | GPU MiB per object | lookups per pixel | 2-deg Sun | "
                  "10-deg Sun | ground at 10 deg elevation, 10-deg Sun |")
            print("|---|---|---|---|---|---|")

            def relight_T(oi, d, a):
                st = stores[oi]
                return st.sun(d, a)[..., None] * result.objects[oi].albedo

            add("T itself (offline, no viewport)", relight_T, 0.0, "-")
            side, nbytes = sp.atlas_layout_bytes(stores[0].directions.size, R)
            if side <= 16384:
                def relight_sparse(oi, d, a):
                    st = stores[oi]
                    tables = sp.cached_tables(st.directions, sp.TABLE_SIZE, a, "linear")
                    return tx.viewport_direct(st, tables, d)[..., None] * \
                        result.objects[oi].albedo

                taps = max(sp.cached_tables(stores[0].directions, sp.TABLE_SIZE, a, "linear")[0]
                           .shape[-1] for a in ANGLES)
                add(f"T through sparse tables ({side}^2 8-bit atlas"
                    + (", over the budget)" if nbytes > args.gpu_budget << 20 else ")"),
                    relight_sparse, nbytes / 2**20, 4 * (2 * taps // 3 + taps) + 1)
            # the block viewport of every object, fitted here where auto showed another
            views = [b.view if b.view is not None else bv.fit(st, **{k: v for k, v in bv.choose(
                st, s.table_size, args.gpu_budget << 20).items() if k in ("block", "k")})
                for b, st in zip(result.objects, stores)]

            def relight_blocks(oi, d, a):   # through the viewport's tables (bilinear)
                idx, w = tt.table_weights(stores[oi].directions, d, s.table_size, a)
                return views[oi].relight_weights(idx, w)[..., None] * result.objects[oi].albedo

            v0 = views[0]
            add(f"blocks {v0.block}^2 x {v0.k} comps ({v0.method})", relight_blocks,
                v0.gpu_bytes(s.table_size)["total_bytes"] / 2**20, bv.lookups_per_pixel(v0.k))

            # (an object whose map auto's trial on sampled tiles rejected has none: no row)
            maps = [b.found_horizon for b in result.objects]

            def relight_horizon(oi, d, a):
                return maps[oi].direct(d, a)[..., None] * result.objects[oi].albedo

            if all(m is not None for m in maps):
                hmib = maps[0].gpu_bytes() / 2**20
                add(f"horizons, {maps[0].azimuths} azimuths at {maps[0].horizon_resolution}^2"
                    + (" (over the budget)" if hmib > args.gpu_budget else ""),
                    relight_horizon, hmib, HORIZON_LOOKUPS)

            def relight_shown(oi, d, a):   # what --viewport auto shows, per object
                b = result.objects[oi]
                if b.horizon is not None:
                    return relight_horizon(oi, d, a)
                if b.view is not None:
                    return relight_blocks(oi, d, a)
                if b.viewport.get("shows") in ("transport", "T"):
                    return relight_sparse(oi, d, a)
                return relight_pca(oi, d, a)

            def relight_pca(oi, d, a):
                idx, w = tt.table_weights(stores[oi].directions, d, s.table_size, a)
                return result.objects[oi].model.relight(idx, w)[..., None] * \
                    result.objects[oi].albedo

            k = result.objects[0].model.k
            pca_mib = ((-(-k // 3) + 1) * (R + 2) ** 2 * bv.HALF_RGBA) / 2**20
            add(f"global PCA {k} comps" + (" (over the budget)"
                                           if pca_mib > args.gpu_budget else ""),
                relight_pca, pca_mib, 2 * -(-k // 3) + 1)
            shown = ", ".join(f"{b.name} {b.viewport.get('shows')}" for b in result.objects)
            # per object, the figures of the viewport it shows (the report's for the horizons
            # and blocks; T's atlas and the global PCA as in their rows above)
            own = {"transport": (nbytes / 2**20, 4 * (2 * taps // 3 + taps) + 1)
                   if side <= 16384 else None, "T": None,
                   "pca": (pca_mib, 2 * -(-k // 3) + 1)}
            own["T"] = own["transport"]
            figs = [(b.viewport["gpu_mib"], b.viewport.get("lookups_per_pixel", "-"))
                    if b.viewport.get("gpu_mib") is not None else
                    own.get(b.viewport.get("shows")) or ("-", "-") for b in result.objects]
            add(f"**what auto shows** ({shown})", relight_shown,
                " / ".join(f"{m:.1f}" if isinstance(m, float) else str(m) for m, _ in figs),
                " / ".join(str(n) for _, n in figs))
            for st in stores:
                st.abort()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
