"""Benchmark: steerable texture bakes on the bumps patch -- cost, error, bytes, workers.

Prints figures (not a test) and writes JSON:

* per preset: wall time split into Cycles bake calls vs our own work, bytes per storage mode,
  error of the relit texture vs Cycles truth of the same light (same samples, 4x samples) and
  vs a Cycles Sun lamp of the lobe's angular size, for 5 directions (elevations 5..85 deg);
* relight error per storage mode (float / half / u8) against the float result;
* 1 process x 2 threads vs 2 worker processes x 1 thread on the same 8 bakes;

The presets themselves are chosen from measured data by ``relight bench --scene bumps
--write-presets`` (operators/bakes/presets.json); this script measures them in more depth.

Usage: python benchmarks/bench_texture_bake.py [--presets draft,balanced,production]
       [--size demo|test] [--json out/bench/texture_bake.json] [--no-workers]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def machine() -> str:
    return f"{os.cpu_count()} cores {platform.machine()}"


def bench_preset(name: str, size: str, truth: int, tmp: str) -> dict:
    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.steerable.texture import SteerableTexture
    from relightable_textures.lt_addon.io.storage import reconstruction_error
    from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
    from relightable_textures.operators.bakes import steerable_bake as sb
    from relightable_textures.operators.bakes.presets import settings_from_preset

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build("bumps", scene, size)
    obj = bpy.data.objects["Bumps"]
    s = settings_from_preset(name)
    result = sb.run(sb.bake_steerable_texture(scene, obj, s))
    row = {
        "preset": name, "scene": f"bumps-{size}", "vertices": len(obj.data.vertices),
        "order": s.order, "resolution": s.resolution, "samples": s.samples,
        "bounces": s.bounces, "storage": s.storage, "bake_calls": result.bake_calls,
        "bake_seconds": round(result.total_seconds, 2),
        "cycles_seconds": round(result.cycles_seconds, 2),
        "seconds_per_basis": round(result.cycles_seconds / result.bake_calls, 3),
        "overhead_fraction": round(1 - result.cycles_seconds / result.total_seconds, 4),
    }
    # bytes and relight error per storage mode, against the float result
    ref_dirs = [direction_from_az_el(az, el) for az, el in ((30, 20), (150, 45), (270, 70))]
    row["storage_modes"] = {}
    for mode in ("float", "half", "u8"):
        path = os.path.join(tmp, f"{name}-{mode}.exr")
        nbytes = result.texture.save(path, mode)
        back = SteerableTexture.load(path)
        errs = [reconstruction_error(result.texture.relight(d), back.relight(d))["rel_fro"]
                for d in ref_dirs]
        row["storage_modes"][mode] = {"exr_bytes": nbytes, "relight_rel_error": max(errs)}
    if truth:
        gt = sb.run(sb.ground_truth_job(scene, obj, result.texture, s, truth))
        row["sun_angle_deg"] = round(gt["sun_angle_deg"], 2)
        row["directions"] = [
            {"azimuth": round(r["azimuth"], 1), "elevation": round(r["elevation"], 1),
             **{k: round(v["rel_fro"], 4) for k, v in r["errors"].items()}}
            for r in gt["directions"]]
        row["rel_error"] = float(np.mean([d["same_light_4x"] for d in row["directions"]]))
        row["rel_error_vs_sun"] = float(np.mean([d["sun"] for d in row["directions"]]))
    return row


WORKER = r"""
import sys, time, bpy
from relightable_textures.operators.base.cycles_bake import EnvironmentBake
from relightable_textures.lt_addon.steerable.sampled_basis import build_sampled_basis
from relightable_textures.lt_addon.steerable.basis import paper_basis
blend, first, count, threads, res, spp = sys.argv[1], *map(int, sys.argv[2:7])
bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
scene = bpy.context.scene
if threads:
    scene.render.threads_mode = "FIXED"
    scene.render.threads = threads
sb = build_sampled_basis(paper_basis(7))
with EnvironmentBake(scene, bpy.data.objects["Bumps"], res, spp, 2, (128, 256)) as eb:
    for k in range(first, first + count):
        eb.bake(sb.light_environment(k, 128, 256, row_order="bottom_first"))
"""


def bench_workers(size: str, tmp: str, res: int = 256, spp: int = 32, bakes: int = 8) -> dict:
    blend = os.path.join(tmp, "workers.blend")
    subprocess.run([os.path.join(os.path.dirname(sys.executable), "relight"), "scene", "bumps",
                    "--size", size, "--out", blend, "--force"], check=True, capture_output=True)

    def launch(first, count, threads):
        return subprocess.Popen([sys.executable, "-c", WORKER, blend, str(first), str(count),
                                 str(threads), str(res), str(spp)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    t = time.perf_counter()
    assert launch(0, bakes, 0).wait() == 0
    one = time.perf_counter() - t
    t = time.perf_counter()
    procs = [launch(0, bakes // 2, 1), launch(bakes // 2, bakes - bakes // 2, 1)]
    assert all(p.wait() == 0 for p in procs)
    two = time.perf_counter() - t
    return {"bakes": bakes, "resolution": res, "samples": spp,
            "one_process_two_threads_seconds": round(one, 2),
            "two_processes_one_thread_seconds": round(two, 2),
            "speedup_of_workers": round(one / two, 3)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", default="draft,balanced")
    parser.add_argument("--size", default="demo", choices=["test", "demo"])
    parser.add_argument("--truth", type=int, default=5, help="ground-truth directions per preset")
    parser.add_argument("--json", default=os.path.join(ROOT, "out", "bench", "texture_bake.json"))
    parser.add_argument("--no-workers", action="store_true")
    args = parser.parse_args()
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="relight-bench-"))
    os.makedirs(os.path.dirname(args.json), exist_ok=True)
    out = {"machine": machine(), "presets": [], "workers": None}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.presets.split(","):
            row = bench_preset(name, args.size, args.truth, tmp)
            out["presets"].append(row)
            print(f"\n== preset {name}: order {row['order']}, {row['resolution']}^2, "
                  f"{row['samples']} spp, {row['bounces']} bounces on {row['scene']} "
                  f"({row['vertices']} vertices)")
            print(f"   bake {row['bake_seconds']:.2f} s = Cycles {row['cycles_seconds']:.2f} s "
                  f"({row['seconds_per_basis']:.3f} s per basis light) + own work "
                  f"{100 * row['overhead_fraction']:.1f}%")
            for mode, st in row["storage_modes"].items():
                print(f"   storage {mode:5s}: {st['exr_bytes']:>10d} bytes, relight error vs float "
                      f"{st['relight_rel_error']:.2e}")
            if "directions" in row:
                print(f"   rel. RMSE of the relit texture (Sun angle {row['sun_angle_deg']} deg):")
                print("     az      el    same-light  4x-samples  Sun-lamp")
                for d in row["directions"]:
                    print(f"   {d['azimuth']:6.1f} {d['elevation']:6.1f}   {d['same_light']:.4f}"
                          f"      {d['same_light_4x']:.4f}      {d['sun']:.4f}")
        if not args.no_workers:
            out["workers"] = bench_workers(args.size, tmp)
            w = out["workers"]
            print(f"\n== workers: {w['bakes']} bakes at {w['resolution']}^2, {w['samples']} spp: "
                  f"1 process x 2 threads {w['one_process_two_threads_seconds']} s, "
                  f"2 processes x 1 thread {w['two_processes_one_thread_seconds']} s "
                  f"(speed-up {w['speedup_of_workers']})")
    from relightable_textures.lt_addon.io import atomic

    atomic.write_json(args.json, out)
    print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
