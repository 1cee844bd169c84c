"""`relight bench` (development only): sweep every knob that costs time or bytes.

Added to the ``relight`` parser as the ``verb:bench`` plugin (``pyproject.toml``,
:mod:`..lt_addon.plugins`) where this package is installed (a source checkout's venv), absent
from the installed extension. ``--write-presets`` writes the presets chosen
from the bumps sweep as ``presets.json`` in ``--out``, in the schema of
``operators/bakes/presets.py``; adopting them is copying that file over
``operators/bakes/presets.json`` (:data:`PRESETS_PATH`) in a commit. Tooling never writes into
the package.
"""

from __future__ import annotations

import os
import sys
import time

from ..lt_addon.io import atomic

#: the extension's preset file, next to the module that reads it (operators/bakes/presets.py):
#: read here, never written
PRESETS_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                            "operators", "bakes", "presets.json")


def add_parser(sub) -> None:
    """Add the ``bench`` verb to the ``relight`` sub-parsers ``sub``."""
    p = sub.add_parser("bench", help="sweep the knobs that cost time or bytes; JSON, CSV and "
                       "PNG charts with the Pareto-optimal points",
                       description="Texture scenes (bumps, noise): a grid over basis order, "
                                   "samples and resolution, each stored at every precision, "
                                   "against Cycles Sun-lamp references. Transport scenes "
                                   "(statue, room): direction sets x eigentransport d x CPCA "
                                   "clusters against a Cycles environment bake. Per point: bake "
                                   "time (Cycles vs own), peak memory, stored bytes, preview "
                                   "cost, rel. RMSE / PSNR / max error. --quick: test-size "
                                   "scenes, a few minutes; default: demo-size scenes (tens of "
                                   "minutes).")
    p.add_argument("--scene", action="append", choices=("bumps", "noise", "statue", "room"),
                   help="scene to sweep (repeatable; default: all four)")
    p.add_argument("--quick", action="store_true", help="the small sweep (make bench)")
    p.add_argument("--out", default="out/bench", metavar="DIR",
                   help="output folder (default out/bench)")
    p.add_argument("--write-presets", action="store_true", help="store the draft / balanced / "
                   "production presets chosen from the bumps sweep's Pareto front")
    p.set_defaults(func=_cmd_bench)


def _cmd_bench(args) -> int:
    from ..operators.cli.common import EXIT_OK, CliError, can_create_in, progress_printer
    from . import bench

    out_dir = os.path.abspath(args.out)
    parent = os.path.dirname(out_dir)
    if not os.path.isdir(out_dir):
        if not os.path.isdir(parent):
            raise CliError(f"output folder's parent does not exist: {parent}")
        os.makedirs(out_dir)
    if not can_create_in(out_dir):
        raise CliError(f"output folder is not writable: {out_dir}")
    scenes = args.scene or ["bumps", "noise", "statue", "room"]
    if args.write_presets and "bumps" not in scenes:
        raise CliError("--write-presets chooses the presets from the bumps sweep; add "
                       "--scene bumps")
    mode = "quick" if args.quick else "standard"
    if args.write_presets and args.quick:
        raise CliError("--write-presets needs the standard (demo-size) sweep; drop --quick")
    show = progress_printer("bench")
    for name in scenes:
        try:
            report = bench.bench_scene(name, mode, out_dir, on_progress=show)
        except KeyboardInterrupt:
            print(f"bench: cancelled during {name}; finished scenes are in {out_dir}",
                  file=sys.stderr)
            return 130
        print(bench.format_report(report))
        if args.write_presets and name == "bumps":
            try:
                path = write_presets(report, os.path.join(out_dir, "presets.json"))
            except ValueError as exc:
                raise CliError(str(exc)) from None
            print(f"  presets written to {path}; to adopt them: cp {path} {PRESETS_PATH}")
    return EXIT_OK


def write_presets(report: dict, path: str) -> str:
    """Store the presets a ``standard`` bench report of a texture scene chose (atomically).

    Raises ValueError for a quick (test-size) sweep: its tiny resolutions are not presets."""
    if report.get("mode") != "standard":
        raise ValueError("presets come from the standard (demo-size) sweep, not --quick")
    data = {"source": {"command": f"relight bench --scene {report['scene']} --write-presets",
                       "scene": f"{report['scene']}-{report['size']}",
                       "machine": report["machine"], "date": time.strftime("%Y-%m-%d"),
                       "reference": {k: v for k, v in report["reference"].items()
                                     if k != "images"}},
            "presets": report["presets"]}
    atomic.write_json(path, data)
    return path
