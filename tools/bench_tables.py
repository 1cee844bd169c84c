"""Markdown tables for docs/ (results.md and the method pages) from `relight bench` /
bench_cpca JSON output.

Usage: python tools/bench_tables.py [DIR]   (default docs/bench)

Prints, for every ``<scene>.json`` in DIR, the chosen presets (texture scenes) and the Pareto
front of error vs bake time; for ``cpca.json`` the cost per vertex of each method at each target
shading error. Paste the output into the docs page (it is how those tables were made).
"""

from __future__ import annotations

import glob
import json
import os
import sys


def _mb(nbytes: float) -> str:
    return f"{nbytes / 1e6:.2f} MB" if nbytes >= 1e5 else f"{nbytes / 1e3:.1f} kB"


def _setting(p: dict) -> str:
    if "order" in p:
        return (f"N1 {p['order']}, {p['resolution']}², {p['samples']} spp, {p['bounces']} bounces, "
                f"{p['storage']}")
    knob = f"d {p['d']}" if p["model"] == "eigentransport" else \
        f"CPCA k {p['clusters']} (tol {p['tol']:g})"
    return f"{p['direction_set']}, {knob}"


def scene_tables(report: dict) -> str:
    out = [f"### {report['scene']} ({report['size']} size, {report['object']}; "
           f"{len(report['points'])} points, {report['seconds'] / 60:.0f} min on "
           f"{report['machine']}, {report['date']})", ""]
    if "presets" in report:
        out += ["| preset | settings | bake | rel. RMSE | PSNR | stored | preview madds/texel |",
                "|---|---|---|---|---|---|---|"]
        for name, pr in report["presets"].items():
            f, s = pr["figures"], pr["settings"]
            out.append(f"| {name} | {_setting(s)} | {f['bake_seconds']:.1f} s | "
                       f"{f['rel_rmse']:.3f} | {f['psnr_db']:.1f} dB | {_mb(f['stored_bytes'])} | "
                       f"{f['preview_madds']:.0f} |")
        out.append("")
    out += ["Pareto front, error vs bake time:", "",
            "| setting | bake (Cycles) | peak mem | stored | preview | rel. RMSE | PSNR | max abs |",
            "|---|---|---|---|---|---|---|---|"]
    front = sorted((p for p in report["points"] if p["pareto_time"]),
                   key=lambda p: p["bake_seconds"])
    for p in front:
        out.append(f"| {_setting(p)} | {p['bake_seconds']:.2f} s ({p['cycles_seconds']:.2f} s) | "
                   f"{p['peak_rss_mb']:.0f} MB | {_mb(p['stored_bytes'])} | "
                   f"{p['preview_ms']:.2f} ms, {p['preview_madds']:.0f} madds | "
                   f"{p['rel_rmse']:.4f} | {p['psnr_db']:.1f} dB | {p['max_abs_error']:.3g} |")
    return "\n".join(out)


def cpca_tables(rows: list) -> str:
    out = []
    for row in rows:
        targets = list(row["at_target"])
        out += [f"### {row['scene']} ({row['object']}): {row['vertices']} vertices x "
                f"{row['directions']} directions, N = {row['N']}", "",
                "| method | " + " | ".join(f"cost/vertex at error {t}" for t in targets) + " |",
                "|---|" + "---|" * len(targets)]
        for m in row["at_target"][targets[0]]["cost_per_vertex"]:
            cells = []
            for t in targets:
                c = row["at_target"][t]["cost_per_vertex"][m]
                cells.append("not reached" if c is None else f"{c:.1f}")
            out.append(f"| {m} | " + " | ".join(cells) + " |")
        for t in targets:
            a = row["at_target"][t]
            for key, what in (("paper", "the paper's adaptive"), ("auto", "auto")):
                g, sv = a[f"{key}_vs_global_pca"], a[f"{key}_saving_vs_best_fixed"]
                out.append(f"\nAt {t}: {what} is {g:.2f}x cheaper than global PCA (goal 8x) "
                           f"and {100 * sv:+.1f}% vs the best fixed count (goal +15%)."
                           if g and sv is not None else f"\nAt {t}: {what} missed the target.")
        out.append("")
    return "\n".join(out)


def main() -> None:
    folder = sys.argv[1] if len(sys.argv) > 1 else "docs/bench"
    for path in sorted(glob.glob(os.path.join(folder, "*.json"))):
        with open(path) as fh:
            data = json.load(fh)
        if os.path.basename(path) == "cpca.json":
            print(cpca_tables(data))
        elif isinstance(data, dict) and "points" in data:
            print(scene_tables(data))
        print()


if __name__ == "__main__":
    main()
