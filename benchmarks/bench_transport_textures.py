"""Benchmark: the direction-sampled transport bake against the paper's steerable-lobe bake,
measured in the same run on the same scenes and Cycles truths.

Per scene (``bumps``, ``noise``: the patch; ``statue``: Suzanne *and* its ground plane, baked in
the same Cycles calls) it bakes Cycles truths -- radiance under a Sun lamp of 2 and 10 degrees
with the scene's 2 diffuse bounces at four held-out lights (elevations 10, 30, 55, 80 degrees)
-- and then, per setting:

* transport: directions S x indirect samples x resolution, each with the models fitted from the
  same store (PCA at k components, block PCA at a tolerance, and the relight from T itself);
* lobes: the three lobes presets (``operators/bakes/presets.json``).

Per point: bake wall time (Cycles and everything else, fit included), peak anonymous memory
above the start, bytes on disk (what the preview needs, and T), preview cost (texture lookups per
pixel and multiply-adds per texel), and the relative RMSE against the 2- and 10-degree truths
(``sqrt(mean(rel^2))`` over the four lights). Prints each scene's table with the Pareto front
(error vs bake time) marked, the goals of issue 13, and writes JSON + CSV.

Usage: python benchmarks/bench_transport_textures.py [--scenes bumps,noise,statue]
           [--size demo|test] [--quick] [--out out/bench] [--write-presets]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

SCENES = {"bumps": ["Bumps"], "noise": ["Noise"], "statue": ["Statue", "Ground"]}
ANGLES = (2.0, 10.0)
#: The presets' figures add Blender's default Sun (0.526 degrees): the panel shows the figure
#: of the Sun size nearest the scene's (operators/ui/properties.py FIGURE_SUNS).
PRESET_ANGLES = (0.526,) + ANGLES


def _rss():
    from relightable_textures.lt_addon.peak_memory import rss_anon_mb

    return rss_anon_mb()


def combined(errors):
    return float(np.sqrt(np.mean(np.square(errors))))


def build(name, size):
    import bpy

    from relightable_textures import samples

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build(name, scene, size)
    return scene, [bpy.data.objects[n] for n in SCENES[name]]


def truths(scene, objects, R, spp, bounces=2, seed=1, angles=ANGLES):
    """{angle: {light: [image per object]}}: Cycles Sun bakes at the held-out lights
    (``tx.TRUTH_LIGHTS``) for each of :data:`ANGLES`; also used by the low-sun benchmarks
    (``bounces=0``: direct light only)."""
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    out = {}
    for a in angles:
        t0 = time.perf_counter()
        out[a] = run(tx.truth_bakes(scene, objects, tx.TRUTH_LIGHTS, a, bounces, spp, R,
                                    seed=seed))
        print(f"  truth {a:g} deg, {spp} spp, {bounces} bounces, seed {seed}: "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
    return out


def single_bake_seconds(scene, objects, R, bounces=2):
    """Wall time of one 64-spp Cycles radiance bake of the same textures (``bounces``, a
    Sun)."""
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    with EnvironmentBake(scene, objects, R, 64, bounces, (8, 16), mode="radiance",
                         world_sampling="none") as s:
        s.bake_sun_all(direction_from_az_el(10, 60), 1.0, 10.0)       # warm-up (kernels, BVH)
        t0 = time.perf_counter()
        s.bake_sun_all(direction_from_az_el(37, 10), 1.0, 10.0)
        return time.perf_counter() - t0


def _up(img, R):
    from relightable_textures.operators.bakes.texture_transport import _upsample

    return _upsample(img, R)


def errors_for(relight_fn, truth, R):
    """{angle: combined rel. RMSE over lights and objects} for relight_fn(obj_index, d, angle)."""
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.operators.bakes import texture_transport as tx

    out = {}
    for a in ANGLES:
        errs = []
        for (az, el) in tx.TRUTH_LIGHTS:
            for oi, t in enumerate(truth[a][(az, el)]):
                errs.append(tx.rel_rmse(_up(relight_fn(oi, direction_from_az_el(az, el), a), R),
                                        t))
        out[a] = combined(errs)
    return out


def transport_points(scene, objects, truth, R, S, ind_spp, res, models, folder,
                     ind_res=None, label=None, direct="auto", indirect="gather"):
    """Bake once at (S, ind_spp, res; indirect at ``ind_res``, default res / 2; ``indirect``
    gathered by rays, the default, or the steerable term of ``ind_spp`` samples); one row per
    model fitted from that store."""
    from relightable_textures.lt_addon.transport import sparse_tables as sp
    from relightable_textures.lt_addon.transport import texture as tt
    from relightable_textures.lt_addon.transport.bundle import indirect_lookups
    from relightable_textures.lt_addon.transport.gathered_texture import indirect_images
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    ind_res = ind_res or max(8, res // 2)
    st = tx.TransportTextureSettings(directions=f"hemi:{S}:1.5", resolution=res, bounces=2,
                                     indirect_resolution=ind_res,
                                     indirect_samples=ind_spp, model="none", direct=direct,
                                     indirect=indirect)
    t0 = time.perf_counter()
    # resume=False: a kept indirect stage of the previous point (same lights) is not reused
    result = run(tx.bake_transport_textures(scene, objects, st, folder, resume=False))
    bake_s = time.perf_counter() - t0
    cycles = result.seconds.get("direct_cycles", 0) + result.seconds.get("indirect_cycles", 0) \
        + result.seconds.get("albedo_cycles", 0)
    direct_s = result.seconds.get("direct_total", 0.0)
    stores = [b.store for b in result.objects]
    t_bytes = sum(os.path.getsize(s.path) for s in stores)
    ind_bytes = sum(b.indirect.basis_images.nbytes // 2 for b in result.objects if b.indirect)
    # (the gathered term's coefficients: S x k float32 on top of its half-float images)
    ind_bytes += sum(b.indirect.coefficients.nbytes for b in result.objects
                     if getattr(b.indirect, "coefficients", None) is not None)
    alb_bytes = sum(b.albedo.size * 2 for b in result.objects)
    rows = []
    label = label or (f"transport S {S}, {res}^2, indirect {ind_res}^2 "
                      + ("gathered" if indirect == "gather" else f"steerable {ind_spp} spp"))
    for kind, arg in models:
        t1 = time.perf_counter()
        if kind in ("T", "viewport"):
            fitted = [None for _ in stores]
        elif kind == "pca":
            fitted = [tt.fit_texture_pca(s, k=arg) for s in stores]
        else:
            fitted = [tt.fit_block_pca(s, block=16 if res % 16 == 0 else 8, tol=arg)
                      for s in stores]
        fit_s = time.perf_counter() - t1

        def relight(oi, d, a, fitted=fitted):
            b = result.objects[oi]
            b.model = fitted[oi]
            return tx.relight(b, stores[oi], d, a, source="model" if fitted[oi] else "transport")

        def relight_viewport(oi, d, a):
            """What the transport viewport shows: T through 64^2 sparse kernel tables."""
            b, st_ = result.objects[oi], stores[oi]
            tables = sp.cached_tables(st_.directions, sp.TABLE_SIZE, a, "linear")
            out = tx.viewport_direct(st_, tables, d)[..., None] * b.albedo   # 8-bit atlas
            if b.indirect is not None:
                out = out + tx._upsample(indirect_images(b.indirect, d, a), st_.resolution)
            return out

        if kind == "viewport":
            t1 = time.perf_counter()
            for st_ in stores:     # the tables of both sun sizes the errors use
                for a in (2.0, 10.0):
                    sp.cached_tables(st_.directions, sp.TABLE_SIZE, a, "linear")
            # the bake also fits the PCA the World light uses: its fit time counts too
            pca_fit = (rows[-1]["bake_seconds"] - bake_s
                       if rows and rows[-1]["model"] == "pca" else 0.0)
            fit_s = pca_fit + time.perf_counter() - t1
        err = errors_for(relight_viewport if kind == "viewport" else relight, truth, R)
        if kind == "viewport":
            side, nbytes = sp.atlas_layout_bytes(S, res)
            # preview bytes: the 8-bit atlas as Blender holds it (RGBA), per object
            model_bytes = nbytes * len(stores)
            taps = max(sp.cached_tables(stores[0].directions, sp.TABLE_SIZE, a, "linear")[0]
                       .shape[-1] for a in (2.0, 10.0))     # the wider sun's
            lookups = 4 * (2 * taps // 3 + taps) + 1 + indirect_lookups(st)
            madds = 4 * taps + 27
            name = (f"viewport from T (sparse {sp.TABLE_SIZE}^2 tables, up to {taps} taps, "
                    f"8-bit atlas {side}^2)")
        elif kind == "T":
            model_bytes, lookups, madds, name = t_bytes, None, None, "relight from T (offline)"
        elif kind == "pca":
            k = fitted[0].k
            model_bytes = sum(m.U.size * 2 + m.V.size * 4 for m in fitted)
            lookups = 2 * -(-k // 3) + 1 + indirect_lookups(st)
            madds = 3 * k + 27
            name = f"PCA k {k}"
        else:
            model_bytes = sum(sum(u.size for u in m.U) * 2
                              + sum(v.size for v in m.V) * 4 for m in fitted)
            dims = np.concatenate([m.dims for m in fitted])
            lookups, madds = None, int(3 * dims.mean() + 27)
            name = f"block PCA tol {arg} (mean {dims.mean():.1f} comps)"
        rows.append({
            "method": "transport", "setting": f"{label}, {name}", "S": S, "resolution": res,
            "indirect_samples": ind_spp, "indirect_resolution": ind_res, "model": kind,
            "model_arg": arg,
            "bake_seconds": round(bake_s + fit_s, 2), "cycles_seconds": round(cycles, 2),
            "direct_engine": (result.direct or {}).get("engine", "cycles"),
            "direct_seconds": round(direct_s, 2),
            "peak_mem_mb": round(result.peak_rss_mb, 1),
            "stored_bytes": int(model_bytes + ind_bytes + alb_bytes), "transport_bytes": t_bytes,
            "preview_lookups": lookups, "preview_madds_per_texel": madds,
            "err_2deg": round(err[2.0], 4), "err_10deg": round(err[10.0], 4)})
        print(f"  {rows[-1]['setting']}: {rows[-1]['bake_seconds']} s, err 2/10 deg "
              f"{rows[-1]['err_2deg']}/{rows[-1]['err_10deg']}", flush=True)
    for s in stores:
        s.abort()
    return rows


def lobes_points(scene, objects, truth, R):
    """The lobes presets (one object: the first)."""
    from relightable_textures.operators.bakes import steerable_bake as sb
    from relightable_textures.operators.bakes.presets import settings_from_preset

    rows = []
    for name in ("draft", "balanced", "production"):
        s = settings_from_preset(name, storage="float")
        rss0 = _rss()
        t0 = time.perf_counter()
        res = sb.run(sb.bake_steerable_texture(scene, objects[0], s))
        bake_s = time.perf_counter() - t0
        tex = res.texture
        first_only = {a: {k: [v[0]] for k, v in truth[a].items() if isinstance(k, tuple)}
                      for a in ANGLES}
        err = errors_for(lambda oi, d, a: tex.relight(d), first_only, R)
        n = s.order ** 2
        rows.append({
            "method": "lobes", "setting": f"lobes {name}: order {s.order}, {s.resolution}^2, "
                                          f"{s.samples} spp", "S": n, "resolution": s.resolution,
            "indirect_samples": None, "model": "steerable", "model_arg": s.order,
            "bake_seconds": round(bake_s, 2), "cycles_seconds": round(res.cycles_seconds, 2),
            "peak_mem_mb": round(_rss() - rss0, 1),
            "stored_bytes": int(n * s.resolution ** 2 * 3), "transport_bytes": 0,
            "preview_lookups": n, "preview_madds_per_texel": 3 * n,
            "err_2deg": round(err[2.0], 4), "err_10deg": round(err[10.0], 4)})
        print(f"  {rows[-1]['setting']}: {rows[-1]['bake_seconds']} s, err 2/10 deg "
              f"{rows[-1]['err_2deg']}/{rows[-1]['err_10deg']}", flush=True)
    return rows


def front(rows, key="err_10deg"):
    from relightable_textures.devtools.pareto import pareto_mask

    mask = pareto_mask([r["bake_seconds"] for r in rows], [r[key] for r in rows])
    return [bool(m) for m in mask]


def table(rows, title):
    mask = front(rows)
    lines = [f"#### {title}", "",
             "| | setting | bake | peak mem | stored (preview) | T on disk | preview | err 2° | err 10° |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r, m in sorted(zip(rows, mask), key=lambda t: t[0]["bake_seconds"]):
        madds = r.get("preview_madds_per_texel")
        prev = (f"{r['preview_lookups']} lookups" + (f", {madds} madds" if madds else "")
                if r["preview_lookups"] else
                (f"NumPy, {madds} madds" if madds else "offline"))
        lines.append(
            f"| {'**front**' if m else ''} | {r['setting']} | {r['bake_seconds']:.1f} s "
            f"({r['cycles_seconds']:.1f} s Cycles) | {r['peak_mem_mb']:.0f} MB | "
            f"{r['stored_bytes'] / 2**20:.2f} MiB | {r['transport_bytes'] / 2**20:.1f} MiB | "
            f"{prev} | {r['err_2deg']:.3f} | {r['err_10deg']:.3f} |")
    return "\n".join(lines)


#: The extension's transport presets (operators/bakes/presets.py reads them): read here, never
#: written; the tools write theirs into --out.
PACKAGE_PRESETS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                               "operators", "bakes", "transport_presets.json")


def write_presets(report, scene, out_dir):
    """Presets from the measured front of PCA points (they have a live preview): cheapest,
    knee and most accurate by the 10-degree error (devtools.pareto.choose_presets)."""
    from relightable_textures.devtools.pareto import choose_presets

    rows = [r for r in report["scenes"][scene]["rows"]
            if r["method"] == "transport" and r["model"] == "pca"]
    chosen = choose_presets(rows, cost_key="bake_seconds", error_key="err_10deg")
    out = {"source": {
        "rule": "Pareto front of bake time vs rel. RMSE against a 10-degree Cycles Sun with 2 "
                "bounces (4 held-out lights), PCA models only; cheapest / knee / lowest error",
        "command": "python benchmarks/bench_transport_textures.py --write-presets",
        "scene": scene, "size": report["size"], "machine": report["machine"],
        "date": time.strftime("%Y-%m-%d")}, "presets": {}}
    for name, r in chosen.items():
        out["presets"][name] = {
            "settings": {
                "directions": f"hemi:{r['S']}:1.5", "resolution": r["resolution"],
                "indirect_resolution": (r.get("indirect_resolution")
                                        or max(8, r["resolution"] // 2)),
                "table_size": 64 if name == "production" else 32,
                "indirect_samples": r["indirect_samples"], "components": r["model_arg"]},
            "figures": {"bake_seconds": r["bake_seconds"], "rel_rmse": r["err_10deg"],
                        "rel_rmse_2deg": r["err_2deg"], "scene": f"{scene} {report['size']}"},
            "why": r["why"]}
    path = os.path.join(out_dir, "transport_presets.json")   # never into the package
    from relightable_textures.lt_addon.io import atomic

    atomic.write_json(path, out, indent=1)
    print(f"presets written to {path}; to adopt them: cp {path} {PACKAGE_PRESETS}")


def user_bake_row(scene, objects, truth, settings, folder, one, label):
    """Bake ``settings`` as a user's bake runs them (its model, ``--viewport`` as set: under
    ``auto`` the horizons are found and the held-out checks choose per object) and score what
    the viewport shows with the bake's own :func:`...texture_transport.truth_errors` (the
    report's headline) at the held-out lights for the 2- and 10-degree Suns, beside the relight
    from T itself and the fitted PCA. The bake time is the whole bake, horizons included."""
    from relightable_textures.lt_addon.transport.bundle import preview_cost
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    t0 = time.perf_counter()
    result = run(tx.bake_transport_textures(scene, objects, settings, folder, resume=False))
    bake_s = time.perf_counter() - t0
    errs = {a: tx.truth_errors(result, truth[a], a) for a in truth}
    pca = {a: float(np.sqrt(np.mean([r["model"] ** 2 for r in errs[a]["lights"]])))
           if all("model" in r for r in errs[a]["lights"]) else None for a in truth}
    costs = [preview_cost(b.model, settings, b.store, b.view, b.horizon, b.indirect)
             for b in result.objects]
    stores = [b.store for b in result.objects]
    cycles = sum(result.seconds.get(k, 0.0) for k in
                 ("albedo_cycles", "direct_cycles", "indirect_cycles"))
    row = {
        "setting": label, "shows": [b.viewport.get("shows") for b in result.objects],
        "cycles_seconds": round(cycles, 2),
        "bake_seconds": round(bake_s, 2), "single_bakes": round(bake_s / one, 2),
        "stages": {k: round(v, 2) for k, v in result.seconds.items()
                   if k in ("direct_rays", "horizons", "indirect_total", "fit")},
        "peak_mem_mb": round(result.peak_rss_mb, 1),
        "transport_bytes": int(sum(os.path.getsize(s.path) for s in stores)),
        "preview_lookups": max(c.get("texture_lookups_per_pixel", 0) for c in costs),
        # (the global PCA's preview cost states no GPU figure: None, not 0)
        "gpu_mib": (None if any("gpu_mib" not in c and "atlas_mib_8bit" not in c for c in costs)
                    else round(sum(c.get("gpu_mib", c.get("atlas_mib_8bit")) for c in costs), 1)),
        "err_2deg": round(errs[2.0]["headline_rel_rmse"], 4),
        "err_10deg": round(errs[10.0]["headline_rel_rmse"], 4),
        "err_from_T_2deg": round(errs[2.0]["transport_rel_rmse"], 4),
        "err_from_T_10deg": round(errs[10.0]["transport_rel_rmse"], 4),
        **({"err_0526deg": round(errs[0.526]["headline_rel_rmse"], 4),
            "err_from_T_0526deg": round(errs[0.526]["transport_rel_rmse"], 4)}
           if 0.526 in errs else {}),
        "err_pca_10deg": None if pca[10.0] is None else round(pca[10.0], 4)}
    print(f"  {label}: {row['bake_seconds']} s = {row['single_bakes']} single bakes, shows "
          f"{'/'.join(row['shows'])}, err 2/10 deg {row['err_2deg']}/{row['err_10deg']} "
          f"(from T {row['err_from_T_2deg']}/{row['err_from_T_10deg']}), stages "
          f"{row['stages']}", flush=True)
    for s in stores:
        s.abort()
    return row


def preset_points(scene, objects, truth, folder, one):
    """The transport presets baked as users bake them (:func:`user_bake_row`), as rows of the
    sweep: what the panel's presets cost and show, on the same front as the sweep's points
    (whose bakes find no horizons: their model is fitted after the bake)."""
    from relightable_textures.operators.bakes import texture_transport as tx

    with open(PACKAGE_PRESETS) as fh:
        names = list(json.load(fh)["presets"])
    rows = []
    for name in names:
        s = tx.settings_from_preset(name)
        r = user_bake_row(scene, objects, truth, s, folder, one,
                          f"transport preset {name} as users bake it (shows horizons where "
                          f"auto chose them)")
        rows.append({"method": "transport", "setting": r["setting"] + f" [{'/'.join(r['shows'])}]",
                     "S": s.validate().size, "resolution": s.resolution, "indirect_samples": None,
                     "model": "pca", "model_arg": None,
                     "bake_seconds": r["bake_seconds"], "cycles_seconds": r["cycles_seconds"],
                     "peak_mem_mb": r["peak_mem_mb"],
                     "stored_bytes": int((r["gpu_mib"] or 0) * 2**20),
                     "transport_bytes": r["transport_bytes"],
                     "preview_lookups": r["preview_lookups"], "preview_madds_per_texel": None,
                     "err_2deg": r["err_2deg"], "err_10deg": r["err_10deg"]})
    return rows


def measure_presets(out_dir, truth_spp=256, candidates=(), scene_name="bumps"):
    """Bake each transport preset exactly as defined (operators/bakes/transport_presets.json)
    and as a user's bake runs it (:func:`user_bake_row`: PCA model, ``--viewport auto`` with
    its horizons and held-out choice) on the bumps demo at 256^2, score what the viewport shows
    against the 256-spp truths, time it against one 64-spp bake of the same texture in the same
    run, and write the figures into the presets file's ``figures`` blocks (in ``out_dir``).
    ``candidates``: further {field: value} overrides of a preset (``"preset"``: which one,
    balanced by default), measured in the same run for re-choosing the presets (printed, not
    written). ``scene_name`` other than the bumps: the same rows on another demo scene, and no
    presets file is written (the presets' figures are the bumps')."""
    from dataclasses import replace

    from relightable_textures.lt_addon.io import atomic
    from relightable_textures.operators.bakes import texture_transport as tx

    with open(PACKAGE_PRESETS) as fh:
        data = json.load(fh)
    from relightable_textures.operators.base.scene_sun import scene_bounces

    scene, objects = build(scene_name, "demo")
    R = 256
    # the scene's own bounces, as the presets' bakes take them (--bounces -1) and as its
    # render has them: the truths and the one bake the time is divided by alike
    bounces = scene_bounces(scene)
    one = single_bake_seconds(scene, objects, R, bounces)
    print(f"one 64-spp Cycles bake at {R}^2, {bounces} bounces: {one:.2f} s", flush=True)
    truth = truths(scene, objects, R, truth_spp, bounces=bounces, angles=PRESET_ANGLES)
    rows = []
    with tempfile.TemporaryDirectory(dir=out_dir) as folder:
        for name, row in data["presets"].items():
            p = row["settings"]
            r = user_bake_row(scene, objects, truth, tx.settings_from_preset(name), folder, one,
                              f"{name}: " + ", ".join(f"{k} {v}" for k, v in p.items()))
            rows.append(r)
            row["figures"] = {
                "viewport": "/".join(r["shows"]), "bake_seconds": r["bake_seconds"],
                "rel_rmse": r["err_10deg"], "rel_rmse_2deg": r["err_2deg"],
                "rel_rmse_0526deg": r["err_0526deg"],
                "rel_rmse_from_T_0526deg": r["err_from_T_0526deg"],
                "rel_rmse_from_T": r["err_from_T_10deg"],
                "rel_rmse_from_T_2deg": r["err_from_T_2deg"], "rel_rmse_pca": r["err_pca_10deg"],
                "single_bakes": r["single_bakes"], "single_bake_seconds": round(one, 2),
                "stages_seconds": r["stages"], "peak_mem_mb": r["peak_mem_mb"],
                "transport_bytes": r["transport_bytes"], "preview_lookups": r["preview_lookups"],
                "viewport_gpu_mib": r["gpu_mib"], "scene": "bumps demo",
                "truth_samples": truth_spp, "truth_bounces": bounces,
                "date": time.strftime("%Y-%m-%d")}
        for c in candidates:
            c = dict(c)
            base = c.pop("preset", "balanced")
            rows.append(user_bake_row(scene, objects, truth,
                                      replace(tx.settings_from_preset(base), **c), folder,
                                      one, f"{base} with {json.dumps(c)}"))
    path = os.path.join(out_dir, "transport_presets.json")   # never into the package
    if scene_name == "bumps":
        atomic.write_json(path, data, indent=1)
    print(f"\n#### transport presets as users bake them ({scene_name} demo, {R}^2; one 64-spp "
          f"bake {one:.2f} s; truths {truth_spp} spp, {bounces} bounces (the scene's); "
          f"{time.strftime('%Y-%m-%d %H:%M')})\n")
    print("| setting | shows | bake | x one 64-spp bake | stages (s) | GPU MiB | lookups | "
          "err 0.526° | err 2° | err 10° | from T 0.526° / 2° / 10° |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['setting']} | {'/'.join(r['shows'])} | {r['bake_seconds']:.1f} s | "
              f"{r['single_bakes']:.2f} | {r['stages']} | {r['gpu_mib']} | "
              f"{r['preview_lookups']} | {r['err_0526deg']:.4f} | {r['err_2deg']:.4f} | "
              f"{r['err_10deg']:.4f} | {r['err_from_T_0526deg']:.4f} / "
              f"{r['err_from_T_2deg']:.4f} / {r['err_from_T_10deg']:.4f} |")
    if scene_name == "bumps":
        print(f"measured figures written to {path}; to adopt them: cp {path} {PACKAGE_PRESETS}")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="bumps,noise,statue")
    ap.add_argument("--size", choices=("demo", "test"), default="demo")
    ap.add_argument("--quick", action="store_true", help="test-size scenes, fewer points")
    ap.add_argument("--out", default="out/bench")
    ap.add_argument("--counts", help="direction counts to sweep, e.g. 100,200,400,800")
    ap.add_argument("--no-lobes", action="store_true", help="skip the lobes presets")
    ap.add_argument("--resolution", type=int, help="texture side (default 256; 64 with --quick)")
    ap.add_argument("--write-presets", action="store_true",
                    help="choose draft / balanced / production from the first scene's front of "
                         "viewport (PCA) points and write transport_presets.json into --out")
    ap.add_argument("--truth-samples", type=int, help="Cycles samples of the truths (default "
                    "256; 64 with --quick); one 256-spp truth's own noise is 0.011 here")
    ap.add_argument("--measure-presets", action="store_true",
                    help="bake and measure the three transport presets as defined and as a "
                         "user's bake runs them (bumps demo) and write the presets file with "
                         "their figures into --out")
    ap.add_argument("--candidates", default="[]",
                    help="with --measure-presets: a JSON list of overrides of the balanced "
                         "preset to measure in the same run, e.g. "
                         "'[{\"directions\": \"hemi:400:1.5\"}]' (\"preset\": another base)")
    ap.add_argument("--presets-scene", default="bumps", choices=sorted(SCENES),
                    help="with --measure-presets: the demo scene (not the bumps: printed only)")
    args = ap.parse_args(argv)
    if args.measure_presets:
        os.makedirs(args.out, exist_ok=True)
        measure_presets(args.out, args.truth_samples or 256, json.loads(args.candidates),
                        args.presets_scene)
        return 0
    size = "test" if args.quick else args.size
    R = args.resolution or (64 if args.quick else 256)
    spp = args.truth_samples or (64 if args.quick else 256)
    counts = (50, 100, 200) if args.quick else (100, 200, 400, 800)
    if args.counts:
        counts = tuple(int(c) for c in args.counts.split(","))
    ks = (16, 48) if args.quick else (16, 32, 48, 96)
    os.makedirs(args.out, exist_ok=True)
    report = {"machine": f"{os.cpu_count()} cores", "size": size, "resolution": R,
              "truth_samples": spp, "angles": ANGLES, "scenes": {}}
    md = []
    for name in args.scenes.split(","):
        print(f"{name}:", flush=True)
        t_scene = time.perf_counter()
        scene, objects = build(name, size)
        one = single_bake_seconds(scene, objects, R)
        print(f"  one 64-spp Cycles bake at {R}^2: {one:.2f} s", flush=True)
        truth = truths(scene, objects, R, spp)
        rows = []
        models = ([("T", None)] + [("pca", k) for k in ks] + [("viewport", None)]
                  + [("blocks", 0.02)])
        with tempfile.TemporaryDirectory(dir=args.out) as folder:
            for S in counts:
                rows += transport_points(scene, objects, truth, R, S, 64, R, models, folder)
            mid = counts[-2]
            for ind in (16, 256):     # the steerable term's samples, for comparison
                rows += transport_points(scene, objects, truth, R, mid, ind, R,
                                         [("pca", ks[-2])], folder, indirect="steerable")
            rows += transport_points(scene, objects, truth, R, mid, 64, R // 2,
                                     [("pca", ks[-2])], folder)
            if R == 256:   # the presets as users bake them (horizons, viewport auto)
                rows += preset_points(scene, objects, truth, folder, one)
        if not args.no_lobes:
            rows += lobes_points(scene, objects, truth, R)
        for r, m in zip(rows, front(rows)):
            r["pareto_10deg"] = m
        report["scenes"][name] = {"objects": SCENES[name], "single_64spp_bake_seconds": one,
                                  "rows": rows,
                                  "minutes": round((time.perf_counter() - t_scene) / 60, 1)}
        title = (f"{name} ({size}, {' + '.join(SCENES[name])}, {R}^2; one 64-spp bake "
                 f"{one:.1f} s; truths {spp} spp, 2 bounces)")
        md.append(table(rows, title))
        print(md[-1], flush=True)
        with open(os.path.join(args.out, f"transport_textures_{args.scenes.replace(',', '_')}"
                                         ".json"), "w") as fh:
            json.dump(report, fh, indent=1)
    tag = args.scenes.replace(",", "_")
    with open(os.path.join(args.out, f"transport_textures_{tag}.md"), "w") as fh:
        fh.write("\n\n".join(md) + "\n")
    from relightable_textures.devtools.pareto import write_csv

    if args.write_presets:
        write_presets(report, next(iter(report["scenes"])), args.out)
    write_csv(os.path.join(args.out, f"transport_textures_{tag}.csv"),
              [{"scene": s, **r} for s, v in report["scenes"].items() for r in v["rows"]])
    return 0


if __name__ == "__main__":
    sys.exit(main())
