"""The ``relight export`` verb: parsing and printing only; the work is
:func:`.export.export_job`."""

from __future__ import annotations

import json
import os
import sys


def add_parsers(sub) -> None:
    from ..bakes.export import ExportSettings
    from .common import add_setting_options, parse_az_el, parse_rgb

    p = sub.add_parser(
        "export", help="export a transport-texture bake as a directional lightmap (L1 SH, "
        "MonoSH) or an RTI model (PTM, HSH) with a relightable web page",
        description="Fits a format from the object's transport-texture bake (bake-textures "
                    "--method transport) and reports its error against our own relight. "
                    "godot-lightmap: a folder Godot 4.4+ (or 4.3: --godot 4.3) loads as it "
                    "is: the stacked directional lightmap EXR and its .import, a "
                    "LightmapGIData .tres, the object as glTF (UV2 = the bake's UV map) and a "
                    "scene; sh-l1: four half EXRs of raw L1 SH coefficients (world frame, "
                    "Godot's axes); monosh: Bakery's MonoSH (L0 EXR + 8-bit direction PNG, "
                    "world frame, Unity axes) -- all baked for one lighting, --env or --sun; "
                    "sun-indirect: the bounce light of a moving sun as a few basis lightmaps, "
                    "a table of their weights over the sun's direction and a Godot shader. "
                    "rti-ptm / rti-hsh: a folder in the relight tools' layout (info.json, "
                    "plane_<k>.jpg, as OpenLIME reads it) plus index.html, a page that "
                    "relights it with the mouse.")
    p.add_argument("file", metavar="FILE.blend")
    p.add_argument("--object", required=True, metavar="NAME")
    add_setting_options(p, ExportSettings, ("format", "terms", "components", "godot"),
                        defaults=True)
    p.add_argument("--env", metavar="HDR.exr", help="SH formats: light by this equirect EXR")
    add_setting_options(p, ExportSettings, ("rotate",), defaults=True)
    p.add_argument("--sun", type=parse_az_el, metavar="AZ,EL",
                   help="SH formats: light by a sun (azimuth, elevation in degrees)")
    add_setting_options(p, ExportSettings, ("sun_angle", "strength"), defaults=True)
    p.add_argument("--color", type=parse_rgb, default=(1.0, 1.0, 1.0), metavar="R,G,B")
    add_setting_options(p, ExportSettings, ("exposure", "held_out"), defaults=True)
    p.add_argument("--out", metavar="DIR", help="output folder (default: next to the .blend, "
                   "<name>_relight/)")
    p.add_argument("--force", action="store_true", help="replace existing export files")
    from .common import add_device_option
    add_device_option(p)
    p.set_defaults(func=_cmd_export)


def _cmd_export(args) -> int:
    import bpy

    from .common import (EXIT_OK, CliError, bake_device, check_input_blend, check_output_dir,
                           open_object, run_job)
    from ..base.cycles_bake import BakeInputError
    from ..bakes.export import ExportSettings, export_job

    path = check_input_blend(args.file)
    settings = ExportSettings(format=args.format, terms=args.terms, godot=args.godot,
                              components=args.components,
                              env=os.path.abspath(args.env) if args.env else None,
                              rotate=args.rotate, sun=args.sun, sun_angle=args.sun_angle,
                              strength=args.strength, color=args.color,
                              exposure=args.exposure, held_out=args.held_out)
    try:
        settings.validate()
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    if settings.env is not None and not os.path.isfile(settings.env):
        raise CliError(f"environment not found: {settings.env}")
    out_dir = check_output_dir(args.out, path)
    obj = open_object(path, args.object)
    device = bake_device(args, "export")
    from ...lt_addon.io.transaction import BakeTransaction
    from .common import BakeFailed, describe_sweep

    with BakeTransaction(out_dir) as txn:   # the export's files swap in whole, or not at all
        if any(txn.swept.values()):   # (a planted stage or a linked cache: said, left alone)
            print(f"export: {describe_sweep(txn.swept)}", file=sys.stderr)
        try:
            result = run_job(export_job(bpy.context.scene, obj, settings, txn.stage,
                                        args.force), "export", device)
        except (BakeInputError, ValueError) as exc:
            txn.rollback()
            raise CliError(f"nothing was written: {exc}") from None
        except KeyboardInterrupt:
            txn.rollback()
            print("export: cancelled; nothing was written", file=sys.stderr)
            return 130
        try:
            txn.commit()
        except Exception as exc:
            txn.rollback()
            raise BakeFailed(exc, out_dir, path, txn.stage) from exc
        result = txn.final_result(result)
    rep = result.report
    print(json.dumps({k: rep[k] for k in ("object", "format", "bytes_per_texel",
                                          "error_vs_our_relight", "timings")
                      if k in rep} | {"files": result.files}, default=float))
    return EXIT_OK
