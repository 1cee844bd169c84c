"""What the ``relight`` verbs share: the one-line error, argument parsers for lights and colours,
the device and Dask options, opening a .blend's objects, the output checks, driving a job with
progress and Ctrl-C, and :func:`run_bake`, the tail every bake verb ends with."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys

import numpy as np

from ...lt_addon.io import atomic
from ...lt_addon.io.names import object_stem

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2


class CliError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


def parse_az_el(text: str) -> tuple[float, float]:
    try:
        az, el = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected AZ,EL in degrees, got {text!r}") from None
    if not (np.isfinite(az) and np.isfinite(el)) or not -90.0 <= el <= 90.0:
        raise argparse.ArgumentTypeError(f"elevation must be in [-90, 90] degrees, got {text!r}")
    return az, el


def parse_rgb(text: str) -> tuple[float, float, float]:
    try:
        rgb = tuple(float(v) for v in text.split(","))
    except ValueError:
        rgb = ()
    if len(rgb) != 3 or not all(np.isfinite(rgb)) or min(rgb) < 0:
        raise argparse.ArgumentTypeError(f"expected R,G,B (three non-negative numbers), got {text!r}")
    return rgb


def parse_point_light(text: str):
    try:
        x, y, z, power = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z,POWER, got {text!r}") from None
    if not all(np.isfinite([x, y, z, power])) or power < 0:
        raise argparse.ArgumentTypeError(f"need finite X,Y,Z and POWER >= 0, got {text!r}")
    return (x, y, z), power


def run_job(job, verb: str, device=None):
    """Drive ``job`` (a :mod:`.jobs` generator) to the end, printing its progress; returns its
    result. Its Cycles bakes run on ``device`` (a :class:`.cycles_device.Device`; None: the
    CPU, as for a job driven by a script that never chose). Ctrl-C (SIGINT) cancels it
    between two steps -- Cycles runs Python callbacks that would swallow a KeyboardInterrupt
    raised in the middle of a bake -- so the job closes cleanly (its ``finally`` blocks
    restore the scene and drop temporary files); a second Ctrl-C stops at once. A cancelled
    job raises KeyboardInterrupt here."""
    import signal

    from ..base import jobs

    asked = []

    def on_sigint(signum, frame):
        if asked:
            raise KeyboardInterrupt
        asked.append(True)
        print(f"{verb}: cancelling after the current step (Ctrl-C again to stop at once)",
              file=sys.stderr, flush=True)

    # SIGBREAK: Windows' Ctrl-Break, which the panel's Run On sends its command
    signums = [signal.SIGINT] + ([signal.SIGBREAK] if hasattr(signal, "SIGBREAK") else [])
    previous = {}
    try:
        for signum in signums:
            previous[signum] = signal.signal(signum, on_sigint)
    except ValueError:   # not the main thread (Blender's own console, say): Ctrl-C as before
        pass
    import contextlib

    from ..base import cycles_device

    printer = progress_printer(verb)
    said = []

    def on_progress(step):   # the device, once the bake has started (a refused one: not at all)
        if device is not None and not said:
            note = f": {device.note}" if device.note else ""
            print(f"{verb}: baking on {device.describe()}{note}", file=sys.stderr, flush=True)
            said.append(True)
        printer(step)

    try:
        with cycles_device.use(device) if device else contextlib.nullcontext():
            result = jobs.run(job, on_progress=on_progress, should_cancel=lambda: bool(asked))
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if asked:   # cancel wins over commit, also when it came after the last step
        raise KeyboardInterrupt
    return result


def add_device_option(p) -> None:
    """--device, shared by the verbs that bake with Cycles."""
    p.add_argument("--device", choices=("auto", "cpu", "gpu"),
                   default=os.environ.get("RELIGHT_DEVICE", "auto"),
                   help="where Cycles bakes (default: $RELIGHT_DEVICE, else auto): auto uses "
                        "the GPU the user chose -- the scene's Cycles device and "
                        "Preferences > System in Blender, the first "
                        "GPU backend Cycles finds in the venv CLI -- else the CPU, and says "
                        "so; cpu forces the CPU; gpu refuses to bake without a GPU. The "
                        "report records the device (CPU and GPU bakes of one seed are different "
                        "sample sets: a resumed bake on another device bakes its chunks again, "
                        "unless --mix-devices)")
    p.add_argument("--threads", type=int, metavar="N", default=None,
                   help="CPU threads of the bake: Cycles, the ray engine and the fit's BLAS "
                        "(default: $RELIGHT_BAKE_THREADS, else 0 = every core). BLAS is kept at "
                        "one thread while Cycles renders or rays are cast either way")
    p.add_argument("--mix-devices", action="store_true",
                   help="resume from chunks an interrupted bake left on another device (CPU "
                        "and GPU bake one seed as different sample sets, so the result mixes "
                        "two; the report counts them as mixed_device_chunks). Without it those "
                        "chunks are baked again")


def bake_device(args, verb: str):
    """The device ``--device`` gives for the open scene, or CliError before any bake call
    (``gpu`` without a GPU). :func:`run_job` says which on stderr when the bake starts."""
    import bpy

    from ..base import cycles_device

    if args.device not in cycles_device.CHOICES:   # only a default from the environment can be
        raise CliError(f"$RELIGHT_DEVICE must be one of {', '.join(cycles_device.CHOICES)}, "
                       f"got {args.device!r}")
    try:
        device = cycles_device.resolve(args.device, bpy.context.scene)
    except cycles_device.DeviceError as exc:
        raise CliError(str(exc)) from None
    threads = getattr(args, "threads", None)
    if threads is None:
        text = os.environ.get("RELIGHT_BAKE_THREADS", "").strip() or "0"
        try:
            threads = int(text)
        except ValueError:
            raise CliError(f"$RELIGHT_BAKE_THREADS must be a whole number, got {text!r}") from None
    if threads < 0:
        raise CliError(f"--threads takes 0 (every core) or a count, got {threads}")
    if getattr(args, "mix_devices", False) or threads:
        import dataclasses

        device = dataclasses.replace(device, mix_devices=bool(getattr(args, "mix_devices", False)),
                                     threads=threads)
    return device


def add_distribution_options(p, what: str) -> None:
    """--no-resume / --workers / --scheduler, shared by the verbs that bake in chunks."""
    p.add_argument("--no-resume", action="store_true",
                   help=f"{what}keep no chunks (by default each finished chunk -- 16 "
                        "directions, one basis light or one material term's 16 directions -- "
                        "is kept in <out>/.relight_cache/ until the bake completes, so a "
                        "cancelled or crashed bake run again redoes only the missing ones)")
    p.add_argument("--workers", type=int, metavar="N",
                   help=f"{what}bake the chunks on a local Dask cluster of N worker processes "
                        "(needs dask[distributed])")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help=f"{what}bake the chunks on the Dask cluster at ADDRESS (e.g. "
                        "tcp://host:8786); its workers need this package and bpy, and must "
                        "read the .blend and --out at the same paths. Connecting trusts that "
                        "cluster with code execution here (the Dask client unpickles what the "
                        "scheduler sends): give only a cluster you trust")
    p.add_argument("--connect-timeout", type=float, default=10.0, metavar="SECONDS",
                   help="with --scheduler: how long to wait for the scheduler to answer before "
                        "giving up (default 10; a scheduler still starting may need more)")


def dask_client(args):
    """The Dask client the options ask for (None: bake here); the caller closes it."""
    if args.workers is None and not args.scheduler:
        return None
    from ..farm import distributed

    if args.workers is not None and args.scheduler:
        raise CliError("give --workers N (a local cluster) or --scheduler ADDRESS, not both")
    if args.no_resume:
        raise CliError("--workers / --scheduler hand chunks to the workers through the chunk "
                       "cache; drop --no-resume")
    if not args.connect_timeout > 0:
        raise CliError(f"--connect-timeout must be > 0 seconds, got {args.connect_timeout:g}")
    try:
        return distributed.connect(args.workers, args.scheduler, timeout=args.connect_timeout)
    except distributed.DistributedError as exc:
        raise CliError(str(exc)) from None


def progress_printer(prefix: str):
    def show(step):   # a jobs.Progress
        print(f"{prefix} [{step.done}/{step.total}] {step.message}", file=sys.stderr,
              flush=True)
    return show


def open_object(path: str, name: str):
    """Open ``path`` and return its object ``name`` (a CliError names the meshes if missing)."""
    import bpy

    from ..base.blend_files import blender_log_to_stderr

    with blender_log_to_stderr():
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    obj = bpy.data.objects.get(name)
    if obj is None:
        raise CliError(f"no object {name!r} in {path}; mesh objects: {_bakeable_meshes()}")
    from ..base.blend_files import activate_scene_of
    from ..base.cycles_bake import BakeInputError

    try:
        activate_scene_of(obj, path)
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    return obj


def _bakeable_meshes() -> str:
    """The mesh objects a bake could name: those in a view layer of a scene (an object only in
    an excluded collection, or in no scene, renders in none), sorted, comma-separated."""
    import bpy

    seen = {o.name for sc in bpy.data.scenes for vl in sc.view_layers for o in vl.objects
            if o.type == "MESH"}
    return ", ".join(sorted(seen)) or "none"


def open_objects(path: str, names: list) -> list:
    """Open ``path`` and return its objects ``names``, all in the first one's scene (objects
    baked together share one scene); a CliError names what is wrong."""
    import bpy

    if len(set(names)) != len(names):
        raise CliError("an --object is given twice")
    objects = [open_object(path, names[0])]
    for name in names[1:]:
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise CliError(f"no object {name!r} in {path}; mesh objects: {_bakeable_meshes()}")
        if obj.name in bpy.context.scene.objects and obj.name not in bpy.context.view_layer.objects:
            raise CliError(f"{obj.name!r} is only in collections excluded from view layer "
                           f"{bpy.context.view_layer.name!r}: Cycles would not render it; "
                           "include its collection or leave it out")
        if obj.name not in bpy.context.view_layer.objects:
            raise CliError(f"{obj.name!r} is not in scene {bpy.context.scene.name!r} with "
                           f"{objects[0].name!r}; objects baked together share one scene")
        objects.append(obj)
    return objects


def refuse_existing(out_dir: str, obj_name: str, suffixes, force: bool, what: str) -> None:
    """Refuse (before any work) to replace ``<out_dir>/<object><suffix>`` without --force."""
    safe = object_stem(obj_name)
    if force:
        return
    for suffix in suffixes:
        if os.path.exists(os.path.join(out_dir, safe + suffix)):
            raise CliError(f"{what} of {obj_name} exists in {out_dir} (use --force to replace it)")


def print_warnings(reports) -> None:
    """Every caveat the bake's reports record (:func:`...lt_addon.caveats.all_warnings`), each
    once, as ``relight: warning: <text>`` on stderr."""
    from ...lt_addon.caveats import all_warnings

    for line in all_warnings(reports):
        print(f"relight: warning: {line}", file=sys.stderr)


def print_direct(direct: dict) -> None:
    """How a per-vertex bake made its direct light (the report's ``direct``): by rays, with how
    close Cycles' bake of the checked directions came, or by Cycles and why (a check past its
    tolerance, or Dask workers that sat idle, are warnings: :func:`print_warnings`)."""
    direct = direct or {}
    if direct.get("engine") == "rays":
        check = direct["vs_cycles"]
        took = f", {direct['ray_seconds']:.2f} s" if "ray_seconds" in direct else ""
        print(f"  direct light by rays ({direct['library']}{took}); Cycles' bake of "
              f"{direct['checked_directions']} of its directions: relative difference "
              f"{check['rel_difference']:.2g}, {100 * check['values_apart']:.2g}% of values "
              "more than 1e-4 apart")
    elif direct:
        print(f"  direct light by Cycles: {direct['why']}")


def print_chunks(rep: dict) -> None:
    """A chunked bake's resume and distribution figures, when there are any."""
    for dev, n in (rep.get("other_device_chunks") or {}).items():
        print(f"  note: {n} chunks an interrupted bake left were baked on {dev}; this bake runs "
              f"on {rep.get('device', {}).get('device', 'CPU')}, a different sample set, so "
              "they were baked again")
    for dev, n in (rep.get("mixed_device_chunks") or {}).items():
        print(f"  note: {n} chunks an interrupted bake left on {dev} were reused (--mix-devices): "
              "the result mixes their sample set with this device's")
    if rep.get("chunks_rejected"):
        print(f"  note: {rep['chunks_rejected']} kept chunk(s) failed their check (checksum, "
              "NaN, shape, range) and were baked again")
    if rep.get("chunks_reused"):
        of = ("chunks (one basis light each)" if "chunk_directions" not in rep else
              f"chunks ({rep['indirect_chunks']} of them indirect lights, the others "
              f"{rep['chunk_directions']} directions each)" if rep.get("indirect_chunks") else
              f"chunks of {rep['chunk_directions']} directions")
        print(f"  resumed: {rep['chunks_reused']} of {rep['chunks_total']} {of} reused from an "
              "interrupted bake")
    dist = rep.get("distributed")
    if dist:
        print(f"  distributed: {dist['chunks']} chunks on {len(dist['workers'])} worker "
              f"processes in {dist['wall_seconds']:.1f} s ({dist['cycles_seconds']:.1f} s "
              f"of Cycles, {dist['file_loads']} .blend loads)")


def check_bake_inputs(args, settings) -> tuple[str, str]:
    """What every bake verb checks before opening the file: the input .blend, the settings
    (``settings.validate()``; a BakeInputError becomes one CLI line), the output folder and
    that the .blend can be saved again. Returns ``(blend path, output folder)``."""
    from ..base.cycles_bake import BakeInputError

    path = check_input_blend(args.file)
    try:
        settings.validate()
    except BakeInputError as exc:
        raise CliError(str(exc)) from None
    out_dir = check_output_dir(args.out, path)
    if not can_create_in(os.path.dirname(path)):
        raise CliError(f"cannot update {path}: its folder is not writable")
    return path, out_dir


def check_output_dir(out: str | None, blend_path: str) -> str:
    """The output folder (default ``<blend>_relight`` next to the .blend, the panel's rule too:
    :func:`...lt_addon.io.names.output_folder`), checked creatable and writable."""
    from ...lt_addon.io.names import output_folder

    out_dir = os.path.abspath(out) if out else output_folder(blend_path)
    parent = os.path.dirname(out_dir)
    if not os.path.isdir(parent):
        raise CliError(f"output folder's parent does not exist: {parent}")
    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise CliError(f"output exists and is not a folder: {out_dir}")
    if not can_create_in(out_dir if os.path.isdir(out_dir) else parent):
        raise CliError(f"output folder is not writable: {out_dir}")
    return out_dir


BLEND_MAGICS = (b"BLENDER", b"\x28\xb5\x2f\xfd", b"\x1f\x8b")  # plain, zstd, gzip (old)


def check_input_blend(path: str) -> str:
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


def can_create_in(folder: str) -> bool:
    """Really try to create (and remove) a file: permission bits lie for root and odd mounts."""
    probe = os.path.join(folder, f".relight-write-probe-{os.getpid()}")
    try:
        with open(probe, "xb"):
            pass
    except OSError:
        return False
    os.remove(probe)
    return True


def check_output_path(path: str, suffix: str, force: bool) -> str:
    path = os.path.abspath(path)
    if not path.lower().endswith(suffix):
        raise CliError(f"output must end in {suffix}: {path}")
    folder = os.path.dirname(path)
    if not os.path.isdir(folder):
        raise CliError(f"output directory does not exist: {folder}")
    if not can_create_in(folder):
        raise CliError(f"output directory is not writable: {folder}")
    if os.path.isdir(path):
        raise CliError(f"output is a directory: {path}")
    if os.path.exists(path) and not force:
        raise CliError(f"output exists (use --force to overwrite): {path}")
    if os.path.exists(path) and not os.access(path, os.W_OK):
        raise CliError(f"output exists and is not writable: {path}")
    return path



def run_bake(args, verb: str, path: str, make_job, *, out_dir: str, kept: str,
             retire: tuple = (), cancelled: str = "no bake file was written",
             errors: tuple = (), prefix: str = ""):
    """The tail every bake verb ends with, as one transaction (:mod:`...lt_addon.io.transaction`):
    the device and Dask options (``args``), the job ``make_job(client, stage)`` writing into
    the staging folder ``stage`` of ``out_dir``, driven with progress and Ctrl-C
    (:func:`run_job`); its errors as one line (a bad input, ``errors`` too, prefixed with
    ``prefix``; a failed Dask chunk); the staged files checked and swapped in, the Blender
    data's paths moved with them, and the .blend at ``path`` saved with the bake's records. A
    failure or a kill at any point leaves ``out_dir`` and the .blend as they were (``retire``:
    globs of the previous bake's files that go when the new bake does not write them). Returns
    the job's result (its paths are the committed ones), or None when cancelled (the verb exits
    130; ``kept`` says what a resume reuses, left out with --no-resume)."""
    from ..farm.distributed import close

    device = bake_device(args, verb)
    client = dask_client(args)   # (an unreachable scheduler: one line, nothing made)
    try:
        return _bake_transaction(args, verb, path, make_job, client, device, out_dir, kept,
                                 retire, cancelled, errors, prefix)
    finally:
        if client is not None:
            close(client)


def _bake_transaction(args, verb, path, make_job, client, device, out_dir, kept, retire,
                      cancelled, errors, prefix):
    """:func:`run_bake`'s transaction: sweep, stage, bake, check, save the .blend aside, swap."""
    from ...lt_addon import faults
    from ...lt_addon.io.transaction import BakeTransaction, ChangedMeanwhile, sweep
    from ..base import blend_files
    from ..base.cycles_bake import BakeInputError
    from ..farm.distributed import DistributedError

    blend_swept = sweep(os.path.dirname(path), stages=False)   # a killed run's temporary .blend
    txn = BakeTransaction(out_dir, blend=path, retire=retire)
    with txn:
        swept = {k: v + blend_swept.get(k, []) for k, v in txn.swept.items()}
        if any(swept.values()):
            print(f"{verb}: {describe_sweep(swept)}", file=sys.stderr)
        try:
            out = run_job(make_job(client, txn.stage), verb, device)
        except (BakeInputError, *errors) as exc:
            raise CliError(f"{prefix}{exc}") from None
        except DistributedError as exc:
            raise CliError(f"{exc}; the finished chunks are kept, the same command resumes") from None
        except KeyboardInterrupt:
            note = "" if args.no_resume else kept
            print(f"{verb}: cancelled; {cancelled}{note}", file=sys.stderr)
            txn.rollback()
            return None
        except Exception as exc:
            txn.rollback()
            raise BakeFailed(exc, out_dir, path, txn.stage) from exc
        with _ctrl_c_deferred(verb) as ctrl_c:   # a commit is not interrupted half-way
            try:   # check; the new .blend under a temporary name; then only renames
                txn.prepare()
                blend_files.move_staged_paths(txn.stage, txn.target)
                out = txn.final_result(out)
                with atomic.atomic_path(path) as tmp:
                    blend_files.save_copy(tmp)
                    faults.checkpoint("blend")
                    if ctrl_c:   # Ctrl-C before the first rename: cancel wins over commit
                        raise KeyboardInterrupt
                    txn.swap(blend_tmp=tmp)
            except KeyboardInterrupt:
                txn.rollback()
                ctrl_c.clear()
                note = "" if args.no_resume else kept
                print(f"{verb}: cancelled before the commit; {cancelled}{note}", file=sys.stderr)
                return None
            except ChangedMeanwhile as exc:
                raise CliError(f"{exc}{'' if args.no_resume else kept}") from None
            except Exception as exc:   # a fault: undone here, told in one line
                txn.rollback()
                raise BakeFailed(exc, out_dir, path, txn.stage) from exc
            txn.finish()
    for warning in getattr(txn, "warnings", []):
        print(f"relight: warning: {warning}", file=sys.stderr)
    return out


@contextlib.contextmanager
def _ctrl_c_deferred(verb: str):
    """Ctrl-C (SIGINT) held while the block runs, then said: the commit of a bake is a few
    renames and its undo, which must not stop half-way."""
    import signal

    asked = []
    try:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: asked.append(True))
    except ValueError:   # not the main thread
        yield asked
        return
    try:
        yield asked   # (the block reads it: before the swap starts, a Ctrl-C still cancels)
    finally:
        signal.signal(signal.SIGINT, previous)
        if asked:
            print(f"{verb}: Ctrl-C came while the bake was being committed; it was finished "
                  "first (undone if it failed)", file=sys.stderr)


class BakeFailed(CliError):
    """A bake that failed after it started: one line (the cause, the file, that the previous
    bake is as it was, and the log with the traceback)."""

    def __init__(self, exc: BaseException, out_dir: str, blend: str, stage: str | None = None):
        from ...lt_addon.errors import one_line
        from ...lt_addon.io.transaction import rewrite_paths

        line = one_line(exc, f"bake into {out_dir} of {blend}",
                        f"nothing was replaced in {out_dir} or {os.path.basename(blend)}")
        # a file of the stage is named where it was going
        super().__init__(rewrite_paths(line, stage, out_dir) if stage else line)


def describe_sweep(swept: dict) -> str:
    """One line on what the sweep of the output folder did (killed runs' debris)."""
    parts = []
    if swept.get("rolled_back"):
        parts.append(f"undid the half-committed bake of a killed run ({len(swept['rolled_back'])})")
    if swept.get("rolled_forward"):
        parts.append(f"finished the commit of a killed run ({len(swept['rolled_forward'])})")
    if swept.get("removed"):
        parts.append(f"removed {len(swept['removed'])} temporary file(s) of killed runs")
    if swept.get("refused"):   # a planted stage, a symlinked cache: for the user to look at
        parts.append("left alone what is not this tool's to recover or remove (look at "
                     f"it): {', '.join(swept['refused'])}")
    return "; ".join(parts)


def add_setting_options(p, cls, names=None, *, what: str = "", defaults: bool = False) -> None:
    """One CLI option per declared field of ``cls`` (:func:`...lt_addon.settings.declared`):
    its flag, type, choices and help. ``defaults`` False: the option's default is None (the
    verb then takes the preset's value); ``what`` prefixes the help ("transport: ") where one
    verb takes two bakes' options."""
    from ...lt_addon.settings import declared

    for s in declared(cls, names):
        kw = {"help": what + s.help}
        if s.choices:
            kw["choices"] = [c[0] for c in s.choices]
            said = [f"{v}: {desc}" for v, _, desc in s.choices if desc]
            if said:
                kw["help"] += " -- " + "; ".join(said)
        elif s.kind in ("int", "float"):
            kw["type"] = s.parse
            kw["metavar"] = "N" if s.kind == "int" else "X"
            if s.lo is not None and s.hi is not None:
                kw["help"] += f" ({s.lo:g}..{s.hi:g})"
            elif s.lo is not None:
                kw["help"] += f" (>= {s.lo:g})"
        if s.metavar:
            kw["metavar"] = s.metavar
        if s.kind == "bool":
            kw = {"help": kw["help"], "action": "store_true"}
        elif s.required:
            kw["required"] = True
        elif defaults:
            kw["default"] = s.default
            if s.default is not None:
                kw["help"] += f" (default {s.default})"
        else:
            kw["default"] = None
        kw["help"] = kw["help"].replace("%", "%%")     # argparse formats help with %
        p.add_argument(s.flag, **kw)
