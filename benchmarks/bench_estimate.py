"""How close the up-front estimate of a transport bake is to the bake (issue 33).

For each resolution: a bake of the bumps scene with the balanced preset and ``--estimate``
implied (the calibration bakes at 64^2 and 128^2 run first, in the same process, so the two
share the machine's state), then the report's estimate per stage against the measured stage
seconds. Prints Markdown.

``--within F`` makes it a check (``make bench`` passes 0.3): each resolution is baked up to
three times, and two of its runs must land within ``F`` of their estimate, else the bench
exits 1. The calibration bakes take seconds, and a busy neighbour on a shared machine during
them moves the extrapolation (four runs in a row on bpy 5.3.0 gave 0.78, 0.91, 1.05 and 1.13;
CI once saw 1.40), so one run proves nothing and a biased estimator fails every run. This
check was a CI test until 2026-12-07 (150 s of each suite: two estimate-and-bake runs of the
test-size bumps at 256^2, whose calibration pair is 128^2 and 256^2); a timing goal belongs
in a benchmark that prints its figures.

Usage: python benchmarks/bench_estimate.py [--size demo|test] [--resolutions 256,512]
       [--within 0.3]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

BIN = os.path.dirname(sys.executable)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="demo", choices=("demo", "test"))
    ap.add_argument("--preset", default="balanced")
    ap.add_argument("--resolutions", default="256,512")
    ap.add_argument("--within", type=float, default=None,
                    help="fail unless two of at most three runs per resolution land within "
                         "this fraction of their estimate (measured / estimated)")
    args = ap.parse_args()
    work = tempfile.mkdtemp(prefix="bench-estimate-")
    blend = os.path.join(work, "bumps.blend")
    subprocess.run([os.path.join(BIN, "relight"), "scene", "bumps", "--size", args.size,
                    "--out", blend], check=True, capture_output=True)
    print(f"Measured {time.strftime('%Y-%m-%d %H:%M')} on {os.cpu_count()} cores: bumps "
          f"{args.size} size, {args.preset} preset, no truths (seconds: estimated / measured)\n")
    print("| resolution | direct | horizons | indirect | fit | other | bake | "
          "measured / estimated | calibration |")
    print("|---|---|---|---|---|---|---|---|---|")
    ratios: dict = {}
    failed = []
    for r, attempt in ((int(x), a) for x in args.resolutions.split(",") for a in range(3)):
        tried = ratios.setdefault(r, [])
        good = sum(abs(q - 1) <= (args.within or 0) for q in tried)
        if tried and (args.within is None or good >= 2 or len(tried) - good >= 2):
            continue
        out = os.path.join(work, f"r{r}-{attempt}")
        p = subprocess.run([os.path.join(BIN, "relight"), "bake-textures", blend, "--object",
                            "Bumps", "--preset", args.preset, "--resolution", str(r),
                            "--out", out, "--no-compare", "--device", "cpu"],
                           capture_output=True, text=True,
                           env=dict(os.environ, RELIGHT_ESTIMATE="1"))
        if p.returncode != 0:
            raise SystemExit(p.stderr[-3000:])
        rep = json.load(open(os.path.join(out, "Bumps_texture_report.json")))
        e, t = rep["estimate"], rep["timings"]
        from_report = {"direct": t.get("direct_total", 0.0) - t.get("horizons", 0.0),
                       "horizons": t.get("horizons", 0.0),
                       "indirect": t.get("indirect_total", 0.0), "fit": t.get("fit", 0.0)}
        from_report["other"] = max(0.0, t["bake_total"] - sum(from_report.values()))
        guess = dict(e["seconds"])     # the indirect term and its PCA: one figure, as printed
        guess["indirect"] = guess.get("indirect", 0.0) + guess.pop("indirect_pca", 0.0)
        cells = [f"{guess.get(s, 0):.1f} / {from_report[s]:.1f}"
                 for s in ("direct", "horizons", "indirect", "fit", "other")]
        print(f"| {r}² | " + " | ".join(cells) + f" | {e['bake']:.1f} / {t['bake_total']:.1f} | "
              f"{e['measured_over_estimated']:.2f} | {e['calibration_seconds']:.1f} s |")
        tried.append(e["measured_over_estimated"])
    if args.within is not None:
        for r, tried in ratios.items():
            if sum(abs(q - 1) <= args.within for q in tried) < 2:
                failed.append(f"{r}^2: {tried}")
        if failed:
            print(f"\nbench_estimate: FAILED: fewer than two runs within {args.within:.0%} of "
                  f"their estimate (measured / estimated): {'; '.join(failed)}", file=sys.stderr)
            return 1
        print(f"\nEvery resolution: two runs within {args.within:.0%} of their estimate.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
