"""How close the up-front estimate of a transport bake is to the bake (issue 33).

For each resolution: a bake of the bumps scene with the balanced preset and ``--estimate``
implied (the calibration bakes at 64^2 and 128^2 run first, in the same process, so the two
share the machine's state), then the report's estimate per stage against the measured stage
seconds. Prints Markdown.

Usage: python benchmarks/bench_estimate.py [--size demo|test] [--resolutions 256,512]
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
    for r in (int(x) for x in args.resolutions.split(",")):
        out = os.path.join(work, f"r{r}")
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
