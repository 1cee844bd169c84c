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

from .. import __version__

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2


class CliError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser that raises instead of exiting, so Blender's process survives."""

    def error(self, message):
        raise CliError(message)


def build_parser() -> argparse.ArgumentParser:
    from ..samples import DESCRIPTIONS, SIZES

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

    p = sub.add_parser("validate", help="reproduce a paper's figures and check them")
    p.add_argument("--paper", required=True, choices=["ashikhmin2002"],
                   help="which paper's figures to reproduce")
    p.set_defaults(func=_cmd_validate)
    return parser


def run(argv: list[str]) -> int:
    """Run one CLI invocation; returns the process exit code (never raises SystemExit)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        return int(args.func(args) or EXIT_OK)
    except CliError as exc:
        print(f"relight: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as exc:  # --help / --version
        return int(exc.code or 0) if not isinstance(exc.code, str) else EXIT_USAGE


def main() -> None:
    """Console-script entry point."""
    sys.exit(run(sys.argv[1:]))


# ---------------------------------------------------------------------------------------------
# Verbs


def _cmd_scene(args) -> int:
    from ..samples import SCENES

    if args.name not in SCENES:
        raise CliError(f"unknown scene {args.name!r}; choose one of: {', '.join(SCENES)}")
    out = _check_output_path(args.out, ".blend", args.force)
    from . import blend_files

    try:
        info = blend_files.write_sample_scene(args.name, args.size, out)
    except (OSError, RuntimeError) as exc:
        raise CliError(f"could not write {out}: {str(exc).strip().splitlines()[-1]}") from exc
    print(f"wrote {out} (scene {args.name}, size {args.size}, "
          f"object {info['relight_object']}: {info['vertices']} vertices)")
    return EXIT_OK


def _cmd_info(args) -> int:
    from . import blend_files

    if args.file is None:
        path = blend_files.current_file()
        if not path:
            raise CliError("no FILE.blend given and no file is open")
    else:
        path = _check_input_blend(args.file)
    listing = blend_files.relightable_listing(path)
    if args.json:
        print(json.dumps(listing, indent=2))
    else:
        print(blend_files.format_listing(listing))
    return EXIT_OK


def _cmd_validate(args) -> int:
    from ..lt_addon import paper_checks

    report = paper_checks.ashikhmin2002_report()
    print(json.dumps(report, indent=2))
    if not paper_checks.all_ok(report):
        bad = [k for k, v in report.items() if isinstance(v, dict) and not v.get("ok", True)]
        print(f"relight: validate: outside tolerance: {', '.join(bad)}", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


# ---------------------------------------------------------------------------------------------
# Input checks (no bpy needed, so they fail fast and identically in every launcher)

BLEND_MAGICS = (b"BLENDER", b"\x28\xb5\x2f\xfd", b"\x1f\x8b")  # plain, zstd, gzip (old)


def _check_input_blend(path: str) -> str:
    path = os.path.abspath(path)
    if not os.path.exists(path):
        raise CliError(f"input file not found: {path}")
    if os.path.isdir(path):
        raise CliError(f"input is a directory, not a .blend file: {path}")
    if not path.lower().endswith(".blend"):
        raise CliError(f"input must be a .blend file: {path}")
    with open(path, "rb") as fh:
        head = fh.read(7)
    if not head.startswith(BLEND_MAGICS):
        raise CliError(f"not a Blender file (bad header): {path}")
    return path


def _can_create_in(folder: str) -> bool:
    """Really try to create (and remove) a file: permission bits lie for root and odd mounts."""
    probe = os.path.join(folder, f".relight-write-probe-{os.getpid()}")
    try:
        with open(probe, "xb"):
            pass
    except OSError:
        return False
    os.remove(probe)
    return True


def _check_output_path(path: str, suffix: str, force: bool) -> str:
    path = os.path.abspath(path)
    if not path.lower().endswith(suffix):
        raise CliError(f"output must end in {suffix}: {path}")
    folder = os.path.dirname(path)
    if not os.path.isdir(folder):
        raise CliError(f"output directory does not exist: {folder}")
    if not _can_create_in(folder):
        raise CliError(f"output directory is not writable: {folder}")
    if os.path.isdir(path):
        raise CliError(f"output is a directory: {path}")
    if os.path.exists(path) and not force:
        raise CliError(f"output exists (use --force to overwrite): {path}")
    if os.path.exists(path) and not os.access(path, os.W_OK):
        raise CliError(f"output exists and is not writable: {path}")
    return path
