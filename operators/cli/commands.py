"""The ``relight`` command line: one argparse definition for every launcher.

Launchers
---------
* venv console script ``relight ...`` and ``python -m relightable_textures ...`` call :func:`main`.
* Inside Blender the extension registers :func:`run` with ``bpy.utils.register_cli_command`` so
  ``blender -b [FILE.blend] --command relight VERB ...`` runs the same verbs.

Errors in the user's input print one line ``relight: error: ...`` to stderr and return exit
code 2; nothing is written in that case (outputs are written to a temporary name in the target
directory and renamed into place only when complete).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from ... import __version__
from ...lt_addon import plugins
from ...lt_addon.io import atomic
from ...lt_addon.io.names import object_stem
from ...lt_addon.transport.bundle import direct_summary
from .common import (CliError, EXIT_FAILURE, EXIT_OK, EXIT_USAGE, add_device_option,
                     add_distribution_options, add_setting_options, bake_device, can_create_in, check_bake_inputs,
                    check_input_blend, check_output_dir, check_output_path, open_object,
                     open_objects, parse_az_el, parse_point_light, parse_rgb, print_chunks,
                     print_direct, print_warnings, refuse_existing, run_bake, run_job)



class _Parser(argparse.ArgumentParser):
    """ArgumentParser that raises instead of exiting, so Blender's process survives. No
    abbreviated options: ``--direct`` must never be taken for ``--directions``."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message):
        raise CliError(message)


#: bake-textures' options, made from the settings dataclasses (lt_addon/settings.py): the
#: transport method's own, the three both methods take, the lobes method's own.
TRANSPORT_OPTIONS = ("directions", "direct", "texel_sampling", "sun_path", "sun_path_step",
                     "study", "sun_angle", "under_horizon", "model",
                     "components", "tol", "indirect", "indirect_rays",
                     "indirect_components", "indirect_samples", "indirect_resolution",
                     "table_size", "viewport", "horizon_azimuths", "horizon_resolution",
                     "gpu_budget")
SHARED_OPTIONS = ("resolution", "bounces", "seed")
LOBES_OPTIONS = ("frame", "order", "samples", "storage", "mode", "world_sampling")


def build_parser() -> argparse.ArgumentParser:
    from ...lt_addon.steerable.calibration import METHODS as CALIBRATIONS
    from ...lt_addon.transport.bundle import TransportTextureSettings
    from ...samples import DESCRIPTIONS, SIZES
    from ..bakes.steerable_bake import TextureBakeSettings

    parser = _Parser(
        prog="relight",
        description="Relightable Textures: bake relightable textures and light transport "
                    "with Cycles and relight them.",
    )
    parser.add_argument("--version", action="version", version=f"relight {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("scene", help="write a sample scene to a .blend file",
                       description="Write a sample scene. Scenes: " + "; ".join(
                           f"{k}: {v}" for k, v in DESCRIPTIONS.items()))
    p.add_argument("name", metavar="NAME", help="one of: " + ", ".join(DESCRIPTIONS))
    p.add_argument("--out", required=True, metavar="FILE.blend", help="output .blend path")
    p.add_argument("--size", choices=SIZES, default="test",
                   help="test: tiny meshes, 16 spp (default); demo: finer meshes, 64 spp")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.set_defaults(func=_cmd_scene)

    p = sub.add_parser("info", help="list the relightable data stored in a .blend file")
    p.add_argument("file", metavar="FILE.blend", nargs="?",
                   help="the .blend to read (inside Blender: defaults to the open file)")
    p.add_argument("--json", action="store_true", help="print the listing as JSON")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("bake-textures", help="bake relightable textures of one or more objects",
                       description="--method transport (default): bake each object's UV texture "
                                   "under S hard Sun lamps (1 sample each, streamed to disk), the "
                                   "albedo, and the indirect light (gathered by rays over the same "
                                   "directions, or --indirect steerable); "
                                   "fit a model (PCA eigen-textures by default) and install a live "
                                   "preview. --method lobes: the paper's broad-lobe bake under the "
                                   "N = order^2 sampled steerable lights. Both write EXR/NPZ files "
                                   "and a JSON report; the .blend gets the bake record and preview.")
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--object", required=True, action="append", metavar="NAME",
                   help="mesh object with a UV map; repeat to bake several objects in the same "
                        "Cycles calls (shadows fall between them; transport method only)")
    p.add_argument("--object-resolution", action="append", metavar="NAME=SIDE",
                   help="transport: this object's texture side instead of --resolution (e.g. "
                        "the ground at 2048 under an object at 1024, so its long shadows get "
                        "texels); objects of one side are baked together, every object still "
                        "casts shadows on the others; repeatable")
    p.add_argument("--method", choices=("transport", "lobes"), default="transport",
                   help="transport: direction-sampled hard-sun bake (default); lobes: the "
                        "paper's steerable-lobe environment bake")
    p.add_argument("--preset", choices=("draft", "balanced", "production"), default="balanced",
                   help="starting values for the settings below (default balanced)")
    add_setting_options(p, TransportTextureSettings, TRANSPORT_OPTIONS, what="transport: ")
    p.add_argument("--target-error", type=float, metavar="E", help="transport: a pilot bake "
                   "chooses the directions and the PCA tolerance to reach relative RMSE E on "
                   "held-out lights; the report says what it chose and achieved")
    p.add_argument("--truth-samples", type=int, default=256,
                   help="transport: Cycles samples of the truth bakes (default 256)")
    p.add_argument("--estimate", action="store_true",
                   help="transport: print what the bake would cost -- time per stage, disk, "
                        "memory, the viewport's GPU memory -- from two calibration bakes at "
                        "64^2 and 128^2 on this machine (a few seconds; larger where the UV "
                        "map's triangles are narrower than a texel at 64^2; a bake of 128^2 or "
                        "less at its size and half of it), and bake nothing. "
                        "A bake "
                        "at 512^2 or more prints this estimate before it starts, then the time "
                        "left in its progress lines, and its report holds estimate and measured "
                        "time ($RELIGHT_ESTIMATE=1: at any size; 0: never)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing bake of the same object in --out")
    _add_uv_map_option(p)
    add_setting_options(p, TransportTextureSettings, SHARED_OPTIONS)
    add_setting_options(p, TextureBakeSettings, LOBES_OPTIONS, what="lobes: ")
    p.add_argument("--truth", type=int, default=0, metavar="K",
                   help="also bake Cycles ground truth for K light directions (elevations 5..85 "
                        "degrees, none a sample centre) and put the errors in the report")
    p.add_argument("--contact-sheet", metavar="PNG", help="with --truth: write a PNG of steered | "
                   "Cycles truth | difference x4 | Cycles Sun for up to 4 directions")
    add_device_option(p)
    add_distribution_options(p, "")
    p.add_argument("--no-compare", action="store_true",
                   help="with --truth and a scene camera, the bake also renders "
                        "<object>[_steerable]_compare.png (preview | Cycles Sun | difference x4 "
                        "from the camera at the lowest held-out light; in the report's timings "
                        "as compare_seconds); this skips it")
    p.add_argument("--out", metavar="DIR", help="output folder (default: next to the .blend, "
                   "<name>_relight/)")
    p.set_defaults(func=_cmd_bake_textures)

    p = sub.add_parser("bake-chunk", help="bake one chunk of a transport bake's directions into "
                                          "its chunk cache (render farms)",
                       description="Bake chunk K (directions 16K..16K+15) of `bake-textures "
                                   "--method transport` with the same objects and settings into "
                                   "<out>/.relight_cache, as a farm task; `bake-textures` with "
                                   "the same arguments then finds every chunk and only fits and "
                                   "writes. A chunk already there is not baked again.")
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--object", required=True, action="append", metavar="NAME")
    p.add_argument("--chunk", required=True, type=int, metavar="K")
    p.add_argument("--preset", choices=("draft", "balanced", "production"), default="balanced")
    p.add_argument("--directions", metavar="SPEC")
    p.add_argument("--direct", choices=("cycles",), default="cycles",
                   help="chunks are Cycles calls (cycles, the only choice: the final "
                        "`bake-textures` must say --direct cycles to use them)")
    p.add_argument("--resolution", type=int)
    p.add_argument("--seed", type=int)
    _add_uv_map_option(p)
    p.add_argument("--out", metavar="DIR", help="the bake's output folder (default: next to "
                   "the .blend, <name>_relight/)")
    add_device_option(p)
    p.set_defaults(func=_cmd_bake_chunk)

    p = sub.add_parser("relight", help="relight a stored steerable texture for one light (NumPy)")
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--object", required=True, metavar="NAME")
    p.add_argument("--light", type=parse_az_el, metavar="AZ,EL",
                   help="light azimuth and elevation in degrees (bake frame, z up)")
    p.add_argument("--intensity", type=float, default=1.0,
                   help="normal irradiance, as a Sun lamp's strength (default 1)")
    p.add_argument("--color", type=parse_rgb, default=(1.0, 1.0, 1.0), metavar="R,G,B")
    p.add_argument("--sun-angle", type=float, default=None, metavar="DEG",
                   help="transport bakes: sun size in degrees (default: the bake's)")
    p.add_argument("--env", metavar="HDR.exr", help="transport bakes: relight under this "
                   "equirectangular environment instead of a sun (direct light)")
    p.add_argument("--rotate", type=float, default=0.0, metavar="DEG",
                   help="with --env: rotate the environment about +z like a world Mapping "
                        "node's Z rotation (Point type)")
    p.add_argument("--source", choices=("viewport", "model", "transport", "horizon", "blocks"),
                   default="viewport",
                   help="transport bakes: relight what the viewport shows for this object "
                        "(viewport, the default: the one the panel and the report's figure "
                        "show -- its horizon map, T through sparse tables, the PCA or blocks), "
                        "or from the fitted model, T itself, the horizon map or the blocks; "
                        "the texture's margin filled from its islands as Cycles' Extend "
                        "margin fills a bake")
    p.add_argument("--out", metavar="IMG.exr", help="write the relit texture (float RGB EXR)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.set_defaults(func=_cmd_relight)

    p = sub.add_parser("compare", help="render the preview next to a Cycles Sun render (PNG)",
                       description="Render the open scene from its camera twice with Cycles: "
                                   "through the relight previews and with the objects' own "
                                   "materials under a real Sun of the same direction and size; "
                                   "writes preview | Cycles | |difference| x 4 as one PNG. The "
                                   ".blend is not changed.")
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--light", required=True, type=parse_az_el, metavar="AZ,EL")
    p.add_argument("--sun-angle", type=float, default=2.0, metavar="DEG")
    p.add_argument("--samples", type=int, default=128, help="Cycles samples of the Sun render")
    p.add_argument("--resolution", type=int, help="square render size (default: the scene's)")
    p.add_argument("--out", required=True, metavar="IMG.png")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser("light-env", help="write the environment image of one steerable light",
                       description="Write the equirectangular EXR of the calibrated steerable "
                                   "light the relight uses, so its Cycles ground truth can be "
                                   "rendered anywhere (Environment Texture, strength 1).")
    p.add_argument("--order", type=int, default=7, help="basis order N1 (default 7)")
    p.add_argument("--light", required=True, type=parse_az_el, metavar="AZ,EL")
    p.add_argument("--height", type=int, default=256, help="image rows (width = 2 x height)")
    p.add_argument("--intensity", type=float, default=1.0)
    p.add_argument("--calibration", choices=CALIBRATIONS, default="steerable_cos")
    p.add_argument("--out", required=True, metavar="ENV.exr")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.set_defaults(func=_cmd_light_env)

    p = sub.add_parser("bake-transport", help="bake per-vertex light transport and fit "
                       "eigentransport (Nowrouzezahrai 2008)",
                       description="T = visibility x cosine per vertex and sample direction "
                                   "of a hard Sun: by shadow rays (Cycles checks 8 directions), "
                                   "or with --bounces (interreflection) or --direct cycles one "
                                   "Cycles vertex bake per direction; then PCA to d "
                                   "eigentransports. Writes an .npz "
                                   "sidecar and a JSON report; the .blend gets the bake record "
                                   "and a per-vertex preview.")
    _add_transport_source_args(p)
    from ..bakes.transport_bake import TransportSettings

    add_setting_options(p, TransportSettings, ("direct",), defaults=True)
    add_setting_options(p, TransportSettings, ("samples",))
    add_setting_options(p.add_mutually_exclusive_group(), TransportSettings,
                        ("energy", "coeffs"))     # default None: the verb's 0.99 when neither
    p.add_argument("--clusters", metavar="auto|K", help="clustered PCA (Mahajan 2007) instead of "
                   "one global PCA: K clusters, or 'auto' for adaptive subdivision by cost; "
                   "--energy is then each cluster's tolerance")
    p.add_argument("--truth", action="store_true", help="also bake the object under the world "
                   "(or a sun-and-sky HDRI) with Cycles and report the error per d")
    p.add_argument("--out", metavar="DIR", help="output folder (default <blend>_relight/)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing transport bake of the same object in --out")
    add_device_option(p)
    add_distribution_options(p, "")
    p.set_defaults(func=_cmd_bake_transport)

    p = sub.add_parser("analyze", help="how many CPCA clusters an object's transport needs "
                       "(Mahajan 2007): JSON (+ charts in a source checkout)",
                       description="Bakes the object's per-vertex transport (as bake-transport), "
                                   "measures patch dimensionality vs size (log-log slope, mu, "
                                   "p*), the CPCA cost per vertex over cluster counts and the "
                                   "adaptive subdivision. Writes <object>_analysis.json (and, "
                                   "from a source checkout with matplotlib, "
                                   "<object>_dimensionality.png and <object>_cost.png); the "
                                   ".blend is not changed.")
    _add_transport_source_args(p)
    p.add_argument("--tol", type=float, default=1e-3, help="CPCA per-cluster unexplained "
                   "energy fraction (default 1e-3: the paper's 99.9%%)")
    p.add_argument("--seeds", type=int, default=8, help="seed vertices of the dimensionality "
                   "curves (default 8)")
    p.add_argument("--rebake", action="store_true",
                   help="bake the transport again even when the object's bake-transport made "
                        "with the same directions and bounces kept its samples (reused by "
                        "default)")
    p.add_argument("--out", metavar="DIR", help="output folder (default <blend>_relight/)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing analysis of the same object in --out")
    add_device_option(p)
    p.set_defaults(func=_cmd_analyze)

    for add_parser in plugins.verbs():   # a source checkout's development verbs (bench)
        add_parser(sub)

    p = sub.add_parser("relight-vertices", help="shade a stored eigentransport bake (NumPy)")
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--object", required=True, metavar="NAME")
    p.add_argument("--env", metavar="HDR.exr", help="equirect RGB EXR (default: the scene world)")
    p.add_argument("--rotate", type=float, default=0.0, metavar="DEG",
                   help="rotate the environment about +z like a world Mapping node's Z "
                        "rotation (Point type), added to the world's own Mapping rotation")
    p.add_argument("--point-light", type=parse_point_light, metavar="X,Y,Z,POWER",
                   help="add an isotropic point light (W); valid outside the convex hull")
    p.add_argument("--out", required=True, metavar="shading.npy",
                   help="per-vertex RGB, shape (V, 3), float32")
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=_cmd_relight_vertices)

    from . import materials as cli_materials
    cli_materials.add_parsers(sub)
    from . import export as cli_export
    cli_export.add_parsers(sub)
    from . import sun_study as cli_sun_study
    cli_sun_study.add_parsers(sub)

    p = sub.add_parser("validate", help="reproduce a paper's figures and check them")
    p.add_argument("--paper", required=True, choices=sorted(PAPER_CHECKS),
                   help="which paper's figures to reproduce")
    p.set_defaults(func=_cmd_validate)
    return parser


def _add_transport_source_args(p) -> None:
    """FILE, --object, --directions and --bounces: what a per-vertex transport bake reads."""
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--object", required=True, metavar="NAME")
    from ..bakes.transport_bake import TransportSettings

    add_setting_options(p, TransportSettings, ("directions", "bounces"), defaults=True)


def _add_uv_map_option(p) -> None:
    """--uv-map: the one UV map every stage bakes into (operators/base/meshes.bake_uv_name)."""
    p.add_argument("--uv-map", metavar="NAME",
                   help="UV map to bake into on every object (default: each object's active "
                        "UV map, the one Cycles' own bake writes into; the report names it). An "
                        "object without it is refused")


#: Options whose value may start with a minus sign and a digit that argparse would take for
#: an option (``--study -33.87,151.21,...``: a southern latitude first).
_SIGNED_VALUES = ("--study",)


def _join_signed_values(argv: list[str]) -> list[str]:
    """``[--study, -33.87,...]`` -> ``[--study=-33.87,...]`` (argparse reads a lone
    ``-33.87,151.21,...`` as an unknown option, not as the value)."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        nxt = argv[i + 1] if i + 1 < len(argv) else None
        if a in _SIGNED_VALUES and nxt and len(nxt) > 1 and nxt[0] == "-" and \
                (nxt[1].isdigit() or nxt[1] == "."):
            out.append(f"{a}={nxt}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def run(argv: list[str]) -> int:
    """Run one CLI invocation; returns the process exit code (never raises SystemExit)."""
    parser = build_parser()
    try:
        args = parser.parse_args(_join_signed_values(list(argv)))
        uv_map = getattr(args, "uv_map", None)
        if uv_map:
            if getattr(args, "workers", None) is not None or getattr(args, "scheduler", None):
                raise CliError("--uv-map is not passed on to Dask workers yet: make that map "
                               "the active UV map in the .blend instead (the default)")
            from ..base.meshes import chosen_uv_map

            with chosen_uv_map(uv_map):
                return int(args.func(args) or EXIT_OK)
        return int(args.func(args) or EXIT_OK)
    except CliError as exc:
        print(f"relight: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as exc:  # --help / --version
        return int(exc.code or 0) if not isinstance(exc.code, str) else EXIT_USAGE
    except KeyboardInterrupt:   # (a bake's own Ctrl-C is handled by run_job: exit 130 there)
        print("relight: cancelled", file=sys.stderr)
        return 130
    except Exception as exc:   # a fault (disk, permission, a bug): one line, the rest in a log
        from ...lt_addon.errors import one_line

        print(f"relight: error: {one_line(exc, 'relight ' + ' '.join(argv))}", file=sys.stderr)
        return EXIT_USAGE


def _keep_stdout_for_results() -> None:
    """Give the CLI's results a stdout of their own, before bpy is imported.

    Blender's C code logs to file descriptor 1, e.g. ``color_management | Using OCIO=...``
    whenever ``$OCIO`` is set (studios set it for ACES; bpy 5.2 itself sets it for every child
    process), which would corrupt ``--json`` output. Descriptor 1 is pointed at stderr, where
    diagnostics belong, and Python's ``sys.stdout`` keeps the original stream."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
        os.dup2(2, 1)
        sys.stdout = os.fdopen(saved, "w", buffering=1, encoding=sys.stdout.encoding,
                               errors=sys.stdout.errors)
    except (OSError, ValueError, AttributeError):  # no real descriptors (embedded, captured)
        pass


def main() -> None:
    """Console-script entry point (``relight`` and ``python -m relightable_textures``)."""
    _keep_stdout_for_results()
    sys.exit(run(sys.argv[1:]))


# ---------------------------------------------------------------------------------------------
# Verbs


def _cmd_scene(args) -> int:
    from ...samples import SCENES

    if args.name not in SCENES:
        raise CliError(f"unknown scene {args.name!r}; choose one of: {', '.join(SCENES)}")
    out = check_output_path(args.out, ".blend", args.force)
    from ..base import blend_files

    try:
        info = blend_files.write_sample_scene(args.name, args.size, out)
    except (OSError, RuntimeError) as exc:
        raise CliError(f"could not write {out}: {str(exc).strip().splitlines()[-1]}") from exc
    print(f"wrote {out} (scene {args.name}, size {args.size}, "
          f"object {info['relight_object']}: {info['vertices']} vertices)")
    return EXIT_OK


def _cmd_info(args) -> int:
    from ..base import blend_files

    if args.file is None:
        path = blend_files.current_file()
        if not path:
            raise CliError("no FILE.blend given and no file is open")
    else:
        path = check_input_blend(args.file)
    listing = blend_files.relightable_listing(path)
    if args.json:
        print(json.dumps(listing, indent=2))
    else:
        print(blend_files.format_listing(listing))
    return EXIT_OK


#: paper name -> (module in lt_addon, report function)
PAPER_CHECKS = {"ashikhmin2002": ("checks.ashikhmin2002", "ashikhmin2002_report"),
                "mahajan2007": ("checks.mahajan2007", "mahajan2007_report")}


def _cmd_validate(args) -> int:
    import importlib

    module_name, function = PAPER_CHECKS[args.paper]
    checks = importlib.import_module(f"...lt_addon.{module_name}", __package__)
    report = getattr(checks, function)()
    print(json.dumps(report, indent=2))
    if not checks.all_ok(report):
        bad = [k for k, v in report.items() if isinstance(v, dict) and not v.get("ok", True)]
        print(f"relight: validate: outside tolerance: {', '.join(bad)}", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def _cmd_bake_textures(args) -> int:
    if args.method == "transport":
        return _cmd_bake_texture_transport(args)
    lobes_only = [f"--{k.replace('_', '-')}" for k in TRANSPORT_OPTIONS + (
                  "target_error", "object_resolution") if getattr(args, k) is not None]
    if lobes_only:
        raise CliError(f"{', '.join(lobes_only)} apply to --method transport, not lobes")
    if len(args.object) > 1:
        raise CliError("--method lobes bakes one object; give --object once "
                       "(or use --method transport for several)")
    args.object = args.object[0]
    import bpy

    from ..bakes import steerable_bake
    from ..base.cycles_bake import BakeInputError
    from ..bakes.presets import settings_from_preset

    path = check_input_blend(args.file)
    overrides = {k: getattr(args, k) for k in SHARED_OPTIONS + LOBES_OPTIONS
                 if getattr(args, k) is not None}
    try:
        settings = settings_from_preset(args.preset, **overrides)
        settings.validate()
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    if args.truth < 0 or args.truth > 32:
        raise CliError(f"--truth takes 0..32 directions, got {args.truth}")
    sheet = None
    if args.contact_sheet:
        if not args.truth:
            raise CliError("--contact-sheet needs --truth K (K >= 1 directions)")
        sheet = check_output_path(args.contact_sheet, ".png", True)
    out_dir = check_output_dir(args.out, path)
    if not can_create_in(os.path.dirname(path)):
        raise CliError(f"cannot update {path}: its folder is not writable")
    started = time.perf_counter()
    obj = open_object(path, args.object)
    refuse_existing(out_dir, obj.name, ("_steerable.exr", "_steerable.json"), args.force,
                     "a steerable bake")
    out = run_bake(   # the same job as the panel's Bake: bake, truths, files, preview
        args, "bake-textures", path,
        lambda client, stage: steerable_bake.lobes_job(bpy.context.scene, obj, settings, stage,
                                                truth=args.truth, sheet_path=sheet,
                                                compare=not args.no_compare,
                                                resume=not args.no_resume, client=client,
                                                blend_path=path),
        out_dir=out_dir,
        kept="; the finished basis lights are kept and the same command resumes from them",
        cancelled="nothing was written")
    if out is None:
        return 130
    report = out.report
    t = report["timings"]
    print(f"baked {obj.name}: {report['exr']} ({report['bytes']['exr_file']} bytes); "
          f"{t['wall_total']:.2f} s in all: bake {t['total_seconds']:.2f} s "
          f"({t['cycles_bake_seconds']:.2f} s in Cycles), truth {t['truth_seconds']:.2f} s, "
          f"camera comparison {t.get('compare_seconds', 0.0):.2f} s; "
          f"{time.perf_counter() - started - t['wall_total']:.2f} s more to open and save the "
          ".blend")
    gt = report.get("ground_truth", {})
    if "headline_rel_rmse" in gt:
        print(f"  error: {gt['headline_rel_rmse']:.3f} ({gt['headline_meaning']})")
    _print_comparison(report.get("comparison"))
    for row in gt.get("directions", []):
        e = row["errors"]
        print(f"  light az {row['azimuth']:6.1f} el {row['elevation']:5.1f}: rel. RMSE vs same "
              f"light {e['same_light']['rel_fro']:.4f}"
              + (f", 4x samples {e['same_light_4x']['rel_fro']:.4f}" if "same_light_4x" in e else "")
              + (f", vs Sun lamp {e['sun']['rel_fro']:.4f}" if "sun" in e else ""))
    print_chunks(report)
    print_warnings([report])
    return EXIT_OK


def _print_comparison(cmp: dict | None) -> None:
    """The bake report's camera-space comparison, in one line (or why there is none)."""
    if not cmp:
        return
    if "png" in cmp:
        print(f"  camera comparison at light az {cmp['azimuth']:g} el {cmp['elevation']:g}: "
              f"{cmp['png']} (rel. RMSE {cmp['rel_rmse_covered_pixels']:.3f} over the "
              f"object's pixels, {cmp['seconds']:.1f} s)")
    else:
        print(f"  no camera comparison: {cmp['skipped']}")


def _estimate_only(args, objects, settings, sides) -> int:
    """``bake-textures --estimate``: the cost of the bake, printed (per group of objects of
    one texture side, ``sides`` {name: side}); nothing baked or written."""
    import bpy

    from ..bakes.estimate import estimate_groups
    from ..base import cycles_device
    from ..base.cycles_bake import BakeInputError

    device = bake_device(args, "bake-textures")
    try:
        with cycles_device.use(device):
            e = run_job(estimate_groups(bpy.context.scene, objects, settings, sides, args.truth,
                                        args.truth_samples), "bake-textures", device)
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    except KeyboardInterrupt:
        return 130
    for line in e["lines"]:
        print(line)
    return EXIT_OK


def _cmd_bake_texture_transport(args) -> int:
    import bpy

    from ..bakes import texture_transport as tx
    from ..base.cycles_bake import BakeInputError

    lobes_only = [f"--{k.replace('_', '-')}" for k in LOBES_OPTIONS + ("contact_sheet",)
                  if getattr(args, k) is not None]
    if lobes_only:
        raise CliError(f"{', '.join(lobes_only)} apply to --method lobes; the transport method "
                       "takes --directions, --resolution, --bounces, --model, --sun-angle")
    path = check_input_blend(args.file)
    overrides = {k: getattr(args, k) for k in TRANSPORT_OPTIONS + SHARED_OPTIONS
                 if getattr(args, k) is not None}
    from ...lt_addon.transport import object_resolution as orr

    try:
        settings = tx.settings_from_preset(args.preset, **overrides)
        settings.validate()
        if args.truth:
            tx.truth_lights(args.truth)
        sides = dict(orr.parse(spec) for spec in args.object_resolution or ())
        orr.groups(args.object, settings.resolution, sides)   # a name not baked: refused
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    if args.truth_samples < 1:
        raise CliError(f"--truth-samples must be >= 1, got {args.truth_samples}")
    if args.target_error is not None and not 0.0 < args.target_error < 1.0:
        raise CliError(f"--target-error must be in (0, 1), got {args.target_error}")
    out_dir = check_output_dir(args.out, path)
    if not can_create_in(os.path.dirname(path)):
        raise CliError(f"cannot update {path}: its folder is not writable")
    objects = open_objects(path, args.object)
    if args.estimate:
        return _estimate_only(args, objects, settings, sides)
    if not args.force:
        for o in objects:
            rp = os.path.join(out_dir, f"{object_stem(o.name)}_texture_report.json")
            if os.path.exists(rp):
                raise CliError(f"a bake of {o.name} exists in {out_dir} (use --force to "
                               "replace it)")
    from ..bakes.estimate import wanted as estimate_wanted

    out = run_bake(
        args, "bake-textures", path,
        lambda client, stage: tx.bake_job(bpy.context.scene, objects, settings, stage,
                                   resolutions=sides, truth=args.truth,
                                   truth_samples=args.truth_samples,
                                   target_error=args.target_error, compare=not args.no_compare,
                                   resume=not args.no_resume, client=client, blend_path=path,
                                   estimator=estimate_wanted(
                                       settings, client, os.environ.get("RELIGHT_ESTIMATE"),
                                       sides)),
        out_dir=out_dir, retire=tx.retire_globs(objects),
        kept=(f"; the finished chunks are kept in {os.path.join(out_dir, tx.CACHE_FOLDER)} and "
              "the same command resumes from them"))
    if out is None:
        return 130
    reports = out.reports
    for i, rep in enumerate(reports):
        t = rep["timings"]
        together = rep["objects_baked_together"]   # one group of one side (--object-resolution)
        first = i == 0 or together != reports[i - 1]["objects_baked_together"]
        print(f"baked {rep['object']}: {rep['directions']} directions at "
              f"{rep['settings']['resolution']}^2, model {rep['model']['kind']}, "
              f"{rep['bytes']['total'] / 2**20:.1f} MiB; {t['wall_total']:.1f} s in all "
              f"(bake {t['bake_total']:.1f} s: "
              + (f"direct on the workers {t['distributed_wall']:.1f} s, "
                 if "distributed_wall" in t else
                 f"direct by rays {t['direct_rays']:.1f} s, " if "direct_rays" in t else
                 f"Cycles direct {t.get('direct_cycles', 0):.1f} s, ")
              + f"indirect ({(rep.get('indirect') or {}).get('method', 'steerable')}) "
                f"{t.get('indirect_total', t.get('indirect_cycles', 0)):.1f} s; "
                f"fit {t['fit']:.1f} s; camera "
              f"comparison {t.get('compare_seconds', 0.0):.1f} s); report {rep['report']}")
        fid = rep.get("model_vs_T") or {}
        if "headline" in fid:
            via = {"transport": "T through sparse tables",
                   "blocks": "a PCA per texel block", "pca": "the PCA",
                   "horizon": "per-texel horizons"}.get(fid.get("viewport"),
                                                        fid.get("viewport", "the model"))
            extra = (f"; the PCA alone {fid['model_headline']:.3f}"
                     if fid.get("viewport") in ("transport", "blocks", "horizon") else "")
            print(f"  the viewport ({via}) vs T itself at the held-out lights: "
                  f"{fid['headline']:.3f} (worst {fid['worst']['rel']:.3f} at elevation "
                  f"{fid['worst']['elevation']:g} deg{extra}; relight --source transport "
                  "shows T)")
        if first:
            print("  " + direct_summary(rep.get("direct") or {}, rep["directions"]))
            taken = rep.get("from_scene") or {}
            if taken:   # what the settings left to the scene (its Light Paths, its Sun)
                print("  from the scene: " + ", ".join(
                    ([f"{taken['bounces']} diffuse bounces (Light Paths)"]
                     if "bounces" in taken else [])
                    + ([f"Sun size {taken['sun_angle']:g} deg"
                        + (" (the scene has no Sun)" if taken.get("no_sun") else "")]
                       if "sun_angle" in taken else [])))
            print_chunks(rep)
        gt = rep.get("ground_truth")
        if gt and first:   # one headline over all objects baked together
            print(f"  error vs Cycles Sun ({gt['sun_angle']:g} deg, {gt['truth_samples']} spp, "
                  f"{rep['settings']['bounces']} bounces) at {len(gt['lights']) // len(together)}"
                  f" held-out lights: {gt['headline_rel_rmse']:.3f} relative RMSE "
                  f"({gt['headline_of']}; from T directly {gt['transport_rel_rmse']:.3f})")
        if rep is reports[0]:
            _print_comparison(rep.get("comparison"))
        te = rep.get("target_error")
        if te:
            print(f"  target {te['target_error']}: chose {te['chosen_directions']} "
                  f"({te.get('why', 'the pilot')}; {te.get('scored', 'T')} scored at "
                  f"{te['pilot_resolution']}^2), tol {te['tol']}; achieved "
                  f"{te.get('achieved', float('nan')):.3f}"
                  f"{'' if te.get('met') else ' (NOT met)'}")
        if rep["glossy"]["materials"]:
            print(f"  note: {rep['glossy']['note']}: "
                  + ", ".join(m["material"] for m in rep["glossy"]["materials"]))
    print_warnings(reports)
    return EXIT_OK


def _cmd_bake_chunk(args) -> int:
    import bpy

    from ..bakes import texture_transport as tx
    from ..base.cycles_bake import BakeInputError, check_bakeable
    from ..bakes.texture_transport import bake_directions

    path = check_input_blend(args.file)
    overrides = {k: getattr(args, k) for k in ("directions", "resolution", "seed")
                 if getattr(args, k) is not None}
    try:
        settings = tx.settings_from_preset(args.preset, **overrides)
        settings.validate()
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    if args.chunk < 0:
        raise CliError(f"--chunk must be 0 or more, got {args.chunk}")
    out_dir = check_output_dir(args.out, path)
    objects = open_objects(path, args.object)
    try:
        for o in objects:
            check_bakeable(o)
        # the whole bake's set: what the scene adds (its Sun's path and size) included
        settings, _ = tx.scene_light_settings(bpy.context.scene, settings)
        dset, _ = tx.resolve_directions(bpy.context.scene, settings)
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    n = -(-dset.size // tx.CHUNK_DIRECTIONS)
    if not 0 <= args.chunk < n:
        raise CliError(f"--chunk must be in 0..{n - 1} ({dset.size} directions in chunks of "
                       f"{tx.CHUNK_DIRECTIONS}), got {args.chunk}")
    start = args.chunk * tx.CHUNK_DIRECTIONS
    stop = min(start + tx.CHUNK_DIRECTIONS, dset.size)
    from ..base import cycles_device

    device = bake_device(args, "bake-chunk")
    with cycles_device.use(device):   # the chunk cache's key names the device
        cache = tx.direct_chunk_cache(bpy.context.scene, objects, settings, out_dir)
        name = f"direct_{start:05d}"
        if os.path.exists(cache.path(name)):
            print(f"chunk {args.chunk}: directions {start}-{stop - 1} are already in "
                  f"{cache.folder}")
            return EXIT_OK
        t0 = time.perf_counter()
        try:
            cycles = bake_directions(bpy.context.scene, objects, settings, start, stop, cache,
                                     device.threads)
        except BakeInputError as exc:
            raise CliError(str(exc)) from None
    print(f"chunk {args.chunk} of {n}: directions {start}-{stop - 1} baked on "
          f"{device.describe()} in {time.perf_counter() - t0:.2f} s ({cycles:.2f} s in Cycles) "
          f"into {cache.path(name)}")
    return EXIT_OK


def _cmd_bake_transport(args) -> int:
    import bpy

    from ..bakes import transport_bake

    settings = transport_bake.TransportSettings(
        directions=args.directions, bounces=args.bounces, samples=args.samples,
        energy=args.energy if args.coeffs is None else None, coeffs=args.coeffs,
        clusters=args.clusters, direct=args.direct)
    if settings.energy is None and settings.coeffs is None:
        settings.energy = 0.99
    path, out_dir = check_bake_inputs(args, settings)
    started = time.perf_counter()
    obj = open_object(path, args.object)
    refuse_existing(out_dir, obj.name, ("_transport.npz", "_transport.json",
                                          "_transport_samples.npy"), args.force,
                     "a transport bake")
    n_vertices = len(obj.data.vertices) if obj.type == "MESH" else 0
    if isinstance(settings.clusters, int) and settings.clusters > n_vertices > 0:
        raise CliError(f"--clusters {settings.clusters} exceeds {obj.name}'s {n_vertices} "
                       f"vertices; use at most {n_vertices} or 'auto'")
    out = run_bake(
        args, "bake-transport", path,
        lambda client, stage: transport_bake.transport_job(
            bpy.context.scene, obj, settings, stage, truth_samples=256 if args.truth else 0,
            resume=not args.no_resume, client=client, blend_path=path),
        out_dir=out_dir,
        kept="; the finished chunks are kept and the same command resumes from them",
        errors=(ValueError,), prefix="nothing was written: ")
    if out is None:
        return 130
    report, t = out.report, out.report["timings"]
    print(f"baked {obj.name}: {report['vertices']} vertices x {report['directions']} directions "
          f"in {t['wall_total']:.2f} s in all (bake {t['total_bake_seconds']:.2f} s, "
          f"{t['directions_per_second']:.1f} directions/s; fit {t['fit_seconds']:.2f} s"
          + (f"; truth {report['ground_truth']['truth_seconds']:.2f} s" if args.truth else "")
          + f"; {time.perf_counter() - started - t['wall_total']:.2f} s more to open and save "
            "the .blend); "
          + (f"CPCA {report['cpca']['clusters']} clusters, {report['cpca']['cost_per_vertex']:.1f}"
             f" multiply-adds per vertex (N = {report['cpca']['N']}), rel. RMS error "
             f"{report['relative_rms_error']:.4f}; " if "cpca" in report else
             f"d = {report['d']} (captured energy {report['captured_energy']:.4f}); ")
          + f"{report['bytes']['sidecar_file']} bytes -> {report['sidecar']}")
    print_direct(report.get("direct"))
    for row in report.get("ground_truth", {}).get("per_d", []):
        what = "CPCA model" if "cpca" in report else f"d = {row['d']:4d}"
        print(f"  {what}: rel. RMS error vs Cycles {row['rel_rms_error']:.4f}")
    if "all_directions_rel_rms_error" in report.get("ground_truth", {}):
        print(f"  all {report['directions']} directions, no PCA: "
              f"{report['ground_truth']['all_directions_rel_rms_error']:.4f} (sampling floor)")
    print_chunks(report)
    print_warnings([report])
    return EXIT_OK


def _cmd_analyze(args) -> int:
    import bpy

    from ..bakes import analyze, transport_bake
    from ..base.cycles_bake import BakeInputError

    path = check_input_blend(args.file)
    try:  # the same direction / bounce checks as bake-transport
        ds = transport_bake.TransportSettings(directions=args.directions,
                                              bounces=args.bounces).validate()
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    if not 0.0 <= args.tol <= 1.0:
        raise CliError(f"--tol must be in [0, 1], got {args.tol}")
    if args.seeds < 1:
        raise CliError(f"--seeds must be >= 1, got {args.seeds}")
    out_dir = check_output_dir(args.out, path)
    started = time.perf_counter()
    obj = open_object(path, args.object)
    refuse_existing(out_dir, obj.name, ("_analysis.json", "_dimensionality.png", "_cost.png"),
                     args.force, "an analysis")
    device = bake_device(args, "analyze")
    try:
        out = run_job(analyze.analysis_job(bpy.context.scene, obj, ds, out_dir, args.bounces,
                                            None, args.tol, args.seeds,
                                            reuse=not args.rebake), "analyze", device)
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    except KeyboardInterrupt:
        print("analyze: cancelled; nothing was written", file=sys.stderr)
        return 130
    report, paths = out.report, out.paths
    dim, best, ad, au = (report["dimensionality"], report["optimum"], report["adaptive"],
                         report["auto"])
    one = report["global_pca"]
    prediction = (f"slope {dim['slope']:.3f}, mu {dim['mu']:.3f}, p* {dim['p_star']:.1f} -> "
                  f"predicted {report['predicted_clusters']} clusters" if dim["mu"] is not None
                  else "no slope (patches too small or saturated): no prediction")
    src = report["transport_source"]
    print(f"analyzed {obj.name}: {report['vertices']} vertices x {report['samples']} directions, "
          f"N = {report['N']}; {prediction}")
    print("  transport: " + (f"reused {src['file']} ({src['why']})" if src["kind"] == "reused"
                              else f"baked in {report['timings']['bake_seconds']:.1f} s "
                                   f"({src['why']})")
          + f"; {report['timings']['wall_total']:.1f} s in all, "
            f"{time.perf_counter() - started - report['timings']['wall_total']:.1f} s more to "
            "open the .blend")
    print(f"  cost per vertex: global PCA {one['cost_per_vertex']:.1f}, best fixed CPCA "
          f"{best['cost_per_vertex']:.1f} at {best['clusters']} clusters, adaptive (paper) "
          f"{ad['cost_per_vertex']:.1f} at {ad['clusters']} clusters, auto "
          f"{au['cost_per_vertex']:.1f} at {au['clusters']} clusters")
    print("  wrote " + ", ".join(paths.values()))
    return EXIT_OK


def _cmd_relight_vertices(args) -> int:
    import bpy

    from ...lt_addon.errors import InputError
    from ...lt_addon.transport.sidecar import read_environment_exr
    from ..preview.relight import relight_vertices

    path = check_input_blend(args.file)
    out = check_output_path(args.out, ".npy", args.force)
    env = None
    if args.env:
        if not os.path.isfile(args.env):
            raise CliError(f"environment file not found: {args.env}")
        try:
            env = read_environment_exr(args.env)
        except (ValueError, OSError) as exc:
            raise CliError(str(exc)) from None
    obj = open_object(path, args.object)
    try:
        values, info, warnings = relight_vertices(bpy.context.scene, obj, env=env,
                                                  point_light=args.point_light,
                                                  rotate=args.rotate)
    except InputError as exc:
        raise CliError(str(exc)) from None
    for w in warnings:
        print(f"relight: warning: {w}", file=sys.stderr)
    with atomic.atomic_path(out) as tmp:
        np.save(tmp, values)
    print(json.dumps({**info, "out": out}))
    return EXIT_OK


def _cmd_relight(args) -> int:
    from ...lt_addon.errors import InputError
    from ...lt_addon.io import exrio
    from ..preview.relight import relight_texture

    path = check_input_blend(args.file)
    out = check_output_path(args.out, ".exr", args.force) if args.out else None
    if (args.light is None) == (args.env is None):
        raise CliError("give exactly one of --light AZ,EL and --env HDR.exr")
    obj = open_object(path, args.object)
    try:
        img, info = relight_texture(obj, light=args.light, env_path=args.env, rotate=args.rotate,
                                    sun_angle=args.sun_angle, intensity=args.intensity,
                                    color=args.color, source=args.source)
    except InputError as exc:
        raise CliError(str(exc)) from None
    if out:
        exrio.write_exr(out, {c: img[..., i] for i, c in enumerate("RGB")}, info,
                        pixel_type="float")
    print(json.dumps({**info, "mean": [float(v) for v in img.mean(axis=(0, 1))],
                      "max": float(img.max()), "out": out}))
    return EXIT_OK


def _cmd_compare(args) -> int:
    import bpy

    from ..preview import compare_render
    from ..base.blend_files import blender_log_to_stderr
    from ..base.cycles_bake import BakeInputError

    path = check_input_blend(args.file)
    out = check_output_path(args.out, ".png", args.force)
    if not 0.0 <= args.sun_angle <= 30.0:
        raise CliError(f"--sun-angle must be in 0..30 degrees, got {args.sun_angle}")
    if args.samples < 1 or (args.resolution is not None and not 8 <= args.resolution <= 4096):
        raise CliError("--samples must be >= 1 and --resolution in 8..4096")
    with blender_log_to_stderr():
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    scene = bpy.context.scene
    objects = [o for o in scene.objects if o.type == "MESH"]
    az, el = args.light
    try:
        with blender_log_to_stderr():
            info = compare_render.compare(scene, objects, az, el, args.sun_angle, out,
                                          args.samples, args.resolution)
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    print(json.dumps(info))
    return EXIT_OK


def _cmd_light_env(args) -> int:
    from ...lt_addon.io import exrio
    from ...lt_addon.sphere.hemisphere import direction_from_az_el
    from ...lt_addon.steerable.calibration import light_environment

    if not 2 <= args.order <= 12:
        raise CliError(f"--order must be in 2..12, got {args.order}")
    if not 8 <= args.height <= 8192:
        raise CliError(f"--height must be in 8..8192, got {args.height}")
    out = check_output_path(args.out, ".exr", args.force)
    az, el = args.light
    env, gain = light_environment(args.order, args.calibration, direction_from_az_el(az, el),
                                  args.height, args.intensity)
    nbytes = exrio.write_exr(out, {c: env for c in "RGB"},
                             {"order": args.order, "light_azimuth": az, "light_elevation": el,
                              "calibration": args.calibration, "gain": gain,
                              "intensity": args.intensity}, pixel_type="float")
    print(f"wrote {out} ({args.height}x{2 * args.height}, {nbytes} bytes; "
          f"min {env.min():.4g}, max {env.max():.4g}: negative lobes are part of the light)")
    return EXIT_OK


# ---------------------------------------------------------------------------------------------
# Input checks (no bpy needed, so they fail fast and identically in every launcher)


