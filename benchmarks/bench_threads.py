"""Thread settings during a bake (issue 36): does NumPy's BLAS contend with Cycles and the ray
engine, and what does each setting cost on this machine?

Bakes the bumps demo scene with the balanced preset (the default bake: albedo and truths by
Cycles, the direct term by rays, the indirect term by Cycles, the PCA fit by BLAS) under each
configuration, alternating them (A B A B ...) so that a shared machine's drift falls on all,
and prints the median of each stage's seconds (from the bake report) and its ratio to the
unmanaged configuration:

* ``unmanaged``: BLAS's threads left as NumPy starts them (every core, also while Cycles
  renders: the bake before issue 36's thread plan; ``RELIGHT_BLAS_POLICY=off``);
* ``default``: the thread plan: BLAS at one thread while Cycles renders and rays are cast, as
  NumPy started it (every core) for the fit;
* ``blas1``: BLAS at one thread for the whole bake (``OPENBLAS_NUM_THREADS=1``);
* ``threads1``: ``--threads 1`` (``RELIGHT_BAKE_THREADS=1``): Cycles, the ray engine and BLAS
  on one thread (what a bake sharing the machine would use).

Usage: python benchmarks/bench_threads.py [--size demo|test] [--reps 2] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

BIN = os.path.dirname(sys.executable)
CONFIGS = {"unmanaged": {"RELIGHT_BLAS_POLICY": "off"}, "default": {},
           "blas1": {"OPENBLAS_NUM_THREADS": "1"}, "threads1": {"RELIGHT_BAKE_THREADS": "1"}}
STAGES = ("albedo_cycles", "direct_rays", "indirect_cycles", "fit", "bake_total",
          "truth_seconds", "preview_seconds", "wall_total")


def run(env_extra: dict, blend: str, out: str, size: str) -> tuple[dict, float]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "RELIGHT_BAKE_THREADS", "OMP_NUM_THREADS",
                        "RELIGHT_BLAS_POLICY")}
    env.update(env_extra)
    t0 = time.perf_counter()
    p = subprocess.run([os.path.join(BIN, "relight"), "bake-textures", blend, "--object", "Bumps",
                        "--preset", "balanced", "--out", out, "--force", "--no-compare",
                        "--device", "cpu"], capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(p.stderr[-3000:])
    rep = json.load(open(os.path.join(out, "Bumps_texture_report.json")))
    t = dict(rep["timings"])
    t["truth_seconds"] = rep.get("ground_truth", {}).get("truth_seconds", 0.0)
    t["process_wall"] = wall
    return t, rep.get("device", {}).get("threads", {})


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="demo", choices=("demo", "test"))
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    work = tempfile.mkdtemp(prefix="bench-threads-")
    blend = os.path.join(work, "bumps.blend")
    subprocess.run([os.path.join(BIN, "relight"), "scene", "bumps", "--size", args.size,
                    "--out", blend], check=True, capture_output=True)
    rows = {c: [] for c in CONFIGS}
    threads = {}
    for rep in range(args.reps):
        for name, extra in CONFIGS.items():
            t, threads[name] = run(extra, blend, os.path.join(work, name), args.size)
            rows[name].append(t)
            print(f"rep {rep + 1} {name}: bake {t['bake_total']:.1f} s, wall "
                  f"{t['process_wall']:.1f} s", file=sys.stderr)
    med = {c: {s: statistics.median(r[s] for r in rows[c] if s in r) for s in STAGES + ("process_wall",)
               if any(s in r for r in rows[c])} for c in CONFIGS}
    print(f"Measured {time.strftime('%Y-%m-%d %H:%M')} on {os.cpu_count()} cores, bumps "
          f"{args.size} size, balanced preset, median of {args.reps} alternating runs "
          "(seconds; ratio to unmanaged)\n")
    print("| stage | " + " | ".join(CONFIGS) + " |")
    print("|---|" + "---|" * len(CONFIGS))
    for s in STAGES + ("process_wall",):
        if s not in med["unmanaged"]:
            continue
        base = med["unmanaged"][s]
        cells = [f"{med[c][s]:.2f}" + (f" ({med[c][s] / base:.2f}x)" if c != "unmanaged" and base
                                       else "") for c in CONFIGS]
        print(f"| {s} | " + " | ".join(cells) + " |")
    print("\nthread settings the reports recorded: " + json.dumps(threads))
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "threads.json"), "w") as fh:
            json.dump({"median": med, "runs": rows, "threads": threads}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
