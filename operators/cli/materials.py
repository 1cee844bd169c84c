"""The material-editing verbs of the ``relight`` CLI: ``bake-materials`` and
``relight-materials`` (precomputed transfer tensors, Sun et al. 2007). Parsing and printing
only; the work is :func:`.material_bake.materials_job` and
:class:`..lt_addon.transport.ptt.TransferTensors`."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from ...lt_addon.io import atomic


def _set_edit(text: str):
    """``MATERIAL.color=R,G,B``, ``MATERIAL.metallic=X`` or ``MATERIAL.roughness=X`` (the
    last two need a bake with glossy anchors: checked against the file)."""
    name, sep, value = text.rpartition("=")
    mat, dot, prop = name.rpartition(".")
    if not sep or not dot or not mat:
        raise argparse.ArgumentTypeError(f"expected MATERIAL.color=R,G,B, got {text!r}")
    if prop == "color":
        from .common import parse_rgb
        return mat, prop, parse_rgb(value)
    if prop in ("roughness", "metallic"):
        try:
            x = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {mat}.{prop}=X, got {text!r}") from None
        if not 0.0 <= x <= 1.0:
            raise argparse.ArgumentTypeError(f"{mat}.{prop} must be in 0..1, got {value}")
        return mat, prop, x
    raise argparse.ArgumentTypeError(f"{prop!r} is not editable: use MATERIAL.color=R,G,B, "
                                     "MATERIAL.metallic=X or MATERIAL.roughness=X")


def add_parsers(sub) -> None:
    from ..bakes.material_bake import MaterialBakeSettings
    from .common import add_setting_options, parse_az_el, parse_rgb

    p = sub.add_parser(
        "bake-materials", help="bake per-vertex transfer tensors so material colours can be "
        "edited with interreflection following (Sun 2007)",
        description="Bakes, per vertex of the objects, the direct light and the light that "
                    "reflected once off each editable material (region) and twice off each "
                    "ordered pair, under hard suns over direction sets (finer for lower "
                    "orders): the direct light by shadow rays (Cycles checks 8 directions; "
                    "--direct cycles bakes them all), the bounces gathered by rays once "
                    "for every direction (or Cycles bakes per direction, --bounce-bake "
                    "cycles). Every rendered mesh of the scene reflects light; materials not "
                    "named with --region keep their colour. Diffuse, or with --anchors "
                    "roughness:... diffuse plus metal: a dielectric's specular layer and "
                    "textures are not modelled. Writes <object>_materials.npz "
                    "and a JSON report; the .blend records where.")
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--object", required=True, action="append", metavar="NAME",
                   help="a receiver mesh (repeat for several: their vertices are stacked in "
                        "this order)")
    p.add_argument("--region", required=True, action="append", metavar="MATERIAL",
                   help="an editable material (repeat for several)")
    add_setting_options(p, MaterialBakeSettings, ("anchors", "anchor_samples", "anchor_directions",
                                                  "direct", "bounce_bake", "rays", "bounces"),
                        defaults=True)
    p.add_argument("--directions", default="hemi:400:1.5", metavar="SPEC",
                   help="direct-light directions (default hemi:400:1.5; 1 sample each)")
    p.add_argument("--one-bounce-directions", default=None, metavar="SPEC",
                   help="one-bounce directions (default hemi:128: with rays as good as 400 on "
                        "the demo room, a sun's shadow edges between them made exact; with "
                        "Cycles bakes 128 at 16 spp erred 9%% less than 64 at 32 spp)")
    p.add_argument("--two-bounce-directions", default="hemi:8", metavar="SPEC")
    add_setting_options(p, MaterialBakeSettings, ("samples", "seed"), defaults=True)
    p.add_argument("--per-corner", action="store_true",
                   help="a value per face corner instead of per vertex: hard edges stay hard "
                        "(about 4x the data and update time on quad meshes)")
    add_setting_options(p, MaterialBakeSettings, ("smoothing",), defaults=True)
    p.add_argument("--truth", action="store_true",
                   help="also bake Cycles truths (two seeds) under the scene's Sun with the "
                        "file's colours and report the error next to their noise floor")
    p.add_argument("--truth-samples", type=int, default=128, metavar="N",
                   help="Cycles samples of each --truth bake (default 128)")
    p.add_argument("--out", metavar="DIR", help="output folder (default <blend>_relight/)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing material bake of the same object in --out")
    from .common import add_device_option, add_distribution_options
    add_device_option(p)
    add_distribution_options(p, "")
    p.set_defaults(func=_cmd_bake_materials)

    p = sub.add_parser("relight-materials", help="shade a material bake with edited colours "
                       "and any light (NumPy)")
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--object", required=True, action="append", metavar="NAME",
                   help="the bake's first object (as given to bake-materials)")
    p.add_argument("--set", action="append", type=_set_edit, default=[],
                   metavar="MATERIAL.color=R,G,B",
                   help="edit a region's colour (linear RGB), or with glossy anchors its "
                        "MATERIAL.metallic=X / MATERIAL.roughness=X; without it, the file's "
                        "materials")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--sun", type=parse_az_el, metavar="AZ,EL",
                       help="a hard distant light (azimuth from +x toward +y, degrees)")
    group.add_argument("--env", metavar="HDR.exr", help="an equirect RGB EXR environment")
    p.add_argument("--rotate", type=float, default=0.0, metavar="DEG",
                   help="--env rotation about +z, like a world Mapping node's Z rotation")
    p.add_argument("--sun-angle", type=float, default=0.0, metavar="DEG")
    p.add_argument("--strength", type=float, default=1.0,
                   help="sun normal irradiance or environment multiplier (default 1)")
    p.add_argument("--color", type=parse_rgb, default=(1.0, 1.0, 1.0), metavar="R,G,B",
                   help="sun colour")
    p.add_argument("--direct", choices=("rays", "rays-at-edges", "baked"), default="rays",
                   help="a sun's direct light: rays (default; a shadow ray per vertex against "
                        "the scene: exact at any sun), rays-at-edges (rays only where the "
                        "baked directions around the sun disagree: faster, can miss a shadow's "
                        "corner between them) or baked (the bake's directions blended, as an "
                        "environment's is)")
    p.add_argument("--out", required=True, metavar="shading.npy",
                   help="outgoing radiance per stacked vertex, shape (V, 3), float32")
    p.add_argument("--compare", metavar="PNG",
                   help="also render, from the scene camera under the scene's Sun, the preview "
                        "before and after the --set edits next to Cycles renders of the same "
                        "materials (the bake's bounces; the camera sees the diffuse part, as "
                        "the preview does) and their differences")
    p.add_argument("--compare-samples", type=int, default=64, metavar="N")
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=_cmd_relight_materials)


def _cmd_bake_materials(args) -> int:
    import bpy

    from ..bakes import material_bake, material_edit
    from .common import (CliError, check_bake_inputs, open_objects, print_chunks, print_direct,
                         print_warnings, refuse_existing, run_bake)

    settings = material_bake.MaterialBakeSettings(
        regions=list(args.region), anchors=args.anchors, bounces=args.bounces,
        anchor_samples=args.anchor_samples, anchor_directions=args.anchor_directions,
        directions=(args.directions, args.one_bounce_directions, args.two_bounce_directions),
        samples=args.samples, seed=args.seed, domain="CORNER" if args.per_corner else "POINT",
        bounce_bake=args.bounce_bake, rays=args.rays, smoothing=args.smoothing,
        direct=args.direct)
    path, out_dir = check_bake_inputs(args, settings)
    started = time.perf_counter()
    objects = open_objects(path, args.object)
    for o in objects:
        if o.type != "MESH":
            raise CliError(f"{o.name!r} is a {o.type.lower()}, not a mesh")
    refuse_existing(out_dir, objects[0].name, ("_materials.npz", "_materials.json"),
                     args.force, "a material bake")
    out = run_bake(
        args, "bake-materials", path,
        lambda client, stage: material_edit.bake_job(
            bpy.context.scene, objects, settings, stage,
            truth_samples=args.truth_samples if args.truth else 0, resume=not args.no_resume,
            client=client, blend_path=path),
        out_dir=out_dir,
        kept="; the finished chunks are kept and the same command resumes from them",
        errors=(ValueError,), prefix="nothing was written: ")
    if out is None:
        return 130
    rep, t = out.report, out.report["timings"]
    shares = rep["energy_shares"]
    what = "face corners" if rep["domain"] == "CORNER" else "vertices"
    g = rep.get("gather")
    rays = (f" + {g['rays_per_origin']} rays from each of {g['origins']} points"
            if g else "")
    print(f"baked {', '.join(rep['objects'])}: {rep['vertices']} {what}, regions "
          f"{', '.join(rep['regions'])} (anchors {rep['anchors']}), {rep['bake_calls']} "
          f"Cycles bakes{rays} in "
          f"{t['wall_total']:.2f} s ({time.perf_counter() - started - t['wall_total']:.2f} s "
          f"more to open and save the .blend); {rep['bytes']['tensors'] / 2**20:.2f} MiB; "
          f"light shares direct {shares['direct']:.3f}, one bounce {shares['one_bounce']:.3f}"
          f", two bounces {shares['two_bounce']:.3f} -> {rep['tensors']}")
    print_direct(rep.get("direct"))
    truth = rep.get("ground_truth")
    if truth:
        print(f"  vs Cycles ({truth['samples']} spp, {truth['light']}): rel. error "
              f"{truth['rel_error']:.4f}, noise floor {truth['noise_floor']:.4f} (two truth "
              f"seeds); without the two-bounce term {truth['rel_error_without_two_bounce']:.4f}")
    print_chunks(rep)
    print_warnings([rep])   # its notes, a direct check past its tolerance
    return 0


def _cmd_relight_materials(args) -> int:
    import bpy

    from ...lt_addon.errors import InputError
    from ...lt_addon.transport.sidecar import read_environment_exr
    from ..bakes import material_edit
    from .common import CliError, check_input_blend, check_output_path, open_objects

    path = check_input_blend(args.file)
    out = check_output_path(args.out, ".npy", args.force)
    png = check_output_path(args.compare, ".png", args.force) if args.compare else None
    if png and (args.sun is not None or args.env):
        raise CliError("--compare renders under the scene's Sun lamp: drop --sun / --env")
    if args.compare_samples < 1:
        raise CliError(f"--compare-samples must be >= 1, got {args.compare_samples}")
    if not np.isfinite(args.strength) or args.strength < 0:
        raise CliError(f"--strength must be >= 0, got {args.strength}")
    if not 0.0 <= args.sun_angle <= 90.0:
        raise CliError(f"--sun-angle must be in 0..90 degrees, got {args.sun_angle}")
    env = None
    if args.env:
        if not os.path.isfile(args.env):
            raise CliError(f"environment file not found: {args.env}")
        try:
            env = read_environment_exr(args.env)
        except (ValueError, OSError) as exc:
            raise CliError(str(exc)) from None
    objects = open_objects(path, args.object[:1])
    try:
        values, info, warnings = material_edit.shade_edits(
            bpy.context.scene, objects[0], args.set, env=env, env_path=args.env,
            rotate=args.rotate, sun=args.sun, sun_angle=args.sun_angle, strength=args.strength,
            color=args.color, direct=args.direct, compare_png=png,
            compare_samples=args.compare_samples)
    except InputError as exc:
        raise CliError(str(exc)) from None
    for w in warnings:
        print(f"relight: warning: {w}", file=sys.stderr)
    with atomic.atomic_path(out) as tmp:
        np.save(tmp, values)
    print(json.dumps({**info, "out": out}))
    return 0
