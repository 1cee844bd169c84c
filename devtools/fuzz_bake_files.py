"""Fuzz every reader of bake files, and the commit recovery, with files a stranger could hand a
user (issue 56; docs/security.md).

Each *case* takes real bakes (made once by the real ``relight`` CLI: a transport-texture bake,
a per-vertex transport bake, a material bake, a lobes bake), copies one into a scratch folder,
damages one of its files, or plants a stage, a journal, a link or a FIFO, then loads it the way
the CLI and the panel do (:func:`lt_addon.bundles.load_bake`, then a relight or shade) or runs
the output folder's sweep (:func:`lt_addon.io.transaction.sweep`). The damage is drawn by
Hypothesis: truncations, byte flips, regions overwritten with random or finite garbage, NPY and
JSON header edits (huge shapes, other dtypes, names with ``..``, absolute paths, huge numbers),
the file replaced by a symlink (to a file outside, to ``/dev/zero``) or a FIFO, planted journals
naming files outside.

Every case must end in one of two outcomes:

- ``loaded``: the reader returned, and what it relit is finite;
- ``refused``: an :class:`~lt_addon.errors.InputError` (``relight: error: <file>: <cause>``,
  exit 2 at the CLI).

Anything else is a ``failure``: another exception (a traceback at the CLI), a case running past
``--case-timeout`` seconds (a hang: a FIFO read, a huge loop), memory past ``--mem-cap-gib``
(this process runs under that RLIMIT_AS), non-finite output, or any change under the scratch
folder's ``outside/`` (a write or delete outside the output folder).

    .venv/bin/python devtools/fuzz_bake_files.py --seconds 3600 --json out/fuzz.json

prints ``fuzz: N cases in S s: X loaded, Y refused, Z failed`` (and each failure); exit 1 when
any failed. ``make fuzz`` runs it for an hour; tests/blender/test_fuzz_smoke.py runs a bounded
smoke of it in CI.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import pathlib
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT.parent) not in sys.path:
    sys.path.insert(0, str(ROOT.parent))

#: the bakes made once (``--make``): (folder name, scene, the command after FILE)
BAKES = {
    "texture": ("bumps", ["bake-textures", "--object", "Bumps", "--preset", "draft",
                          "--directions", "hemi:64", "--resolution", "16", "--truth", "0",
                          "--no-compare"]),
    "vertex": ("statue", ["bake-transport", "--object", "Statue", "--directions", "cube:2"]),
    "lobes": ("statue", ["bake-textures", "--object", "Statue", "--method", "lobes", "--order",
                         "2", "--resolution", "8", "--samples", "2", "--no-compare"]),
    "materials": ("room", ["bake-materials", "--object", "Floor", "--object", "WallLeft",
                           "--region", "RedMaterial", "--directions", "hemi:4",
                           "--one-bounce-directions", "hemi:4", "--two-bounce-directions",
                           "hemi:4", "--samples", "4"]),
}

#: what a bake folder's loader is given: the file the CLI's verbs and the panel open
ENTRY = {"texture": "_texture_report.json", "vertex": "_transport.npz",
         "lobes": "_steerable.exr", "materials": "_materials.npz"}


#: files of a texture bake folder that no reader of ours opens (the other bakes' readers open
#: their entry file alone; their JSON reports are for people): the preview's images, which the panel
#: hands to Blender's own image loader, and the comparison pictures (damaging them would count
#: as "loaded" without testing anything)
PREVIEW_ONLY = re.compile(r"(_preview_|_atlas|_compare)|\.(png|jpg)$")


class Hang(Exception):
    """A case ran past its time limit."""


def make_bakes(folder: pathlib.Path, relight: str) -> None:
    """Run the real CLI once per kind of bake into ``folder/<kind>/``."""
    folder.mkdir(parents=True, exist_ok=True)
    for kind, (scene, args) in BAKES.items():
        out = folder / kind
        if out.is_dir() and any(p.name.endswith(ENTRY[kind]) for p in out.iterdir()):
            continue
        blend = folder / f"{kind}.blend"
        for cmd in (["scene", scene, "--out", str(blend), "--force"],
                    [args[0], str(blend), *args[1:], "--out", str(out), "--force"]):
            r = subprocess.run([relight, *cmd], capture_output=True, text=True, timeout=900)
            if r.returncode != 0:
                raise SystemExit(f"fuzz: error: relight {' '.join(cmd)} failed:\n"
                                 + r.stderr[-2000:])


# ------------------------------------------------------------------------------------------
# loading a bake as the CLI does

def load_and_use(kind: str, entry: str) -> None:
    """Open the bake at ``entry`` and relight or shade it once; raises what the reader
    raises, or AssertionError when the result is not finite."""
    from relightable_textures.lt_addon import bundles

    got = bundles.load_bake(entry)
    sun = np.array([0.3, -0.4, 0.866])
    if kind == "texture":
        from relightable_textures.lt_addon.transport import bundle

        obake, store, _ = got
        outs = [bundle.relight(obake, store, sun, 2.0, source=s)
                for s in ("transport", "model") + (("horizon",) if obake.horizon else ())]
    elif kind == "vertex":
        outs = [got.shade(env=np.full((8, 16, 3), 0.5, np.float32))]
    elif kind == "lobes":
        outs = [got.relight(sun)]
    else:
        from relightable_textures.lt_addon.transport import ptt

        outs = [got.shade(ptt.Sun(sun, 2.0, 3.0))]
    for o in outs:
        if not np.isfinite(np.asarray(o, np.float64)).all():
            raise AssertionError("the relit result is not finite")


# ------------------------------------------------------------------------------------------
# damage

def _npy_header_edit(raw: bytes, rng: random.Random) -> bytes:
    """The NPY header's shape or dtype replaced (same header length when it fits)."""
    if not raw.startswith(b"\x93NUMPY") or len(raw) < 12:
        return raw
    hlen = int.from_bytes(raw[8:10], "little") if raw[6] == 1 else int.from_bytes(raw[8:12], "little")
    start = 10 if raw[6] == 1 else 12
    head = raw[start:start + hlen].decode("latin1")
    choice = rng.randrange(4)
    if choice == 0:
        new = head.replace("'shape': (", f"'shape': ({rng.choice([10**6, 2**31, 10**12])}, ", 1)
    elif choice == 1:
        new = head.replace("'descr': '<f", "'descr': '>f", 1).replace("'descr': '<i", "'descr': '|O", 1)
    elif choice == 2:
        new = head.replace("'descr': '<f2'", "'descr': '<f8'", 1).replace(
            "'descr': '<f4'", "'descr': '<f8'", 1)
    else:
        new = head.replace("'fortran_order': False", "'fortran_order': True", 1)
    body = new.rstrip("\n ")
    if len(body) + 1 > hlen:
        return raw[:start] + new.encode("latin1") + raw[start + hlen:]   # (length now off)
    body = body + " " * (hlen - len(body) - 1) + "\n"
    return raw[:start] + body.encode("latin1") + raw[start + hlen:]


def _json_edit(raw: bytes, rng: random.Random, outside: pathlib.Path) -> bytes:
    try:
        doc = json.loads(raw)
    except ValueError:
        return raw
    paths = []

    def walk(v, at):
        if isinstance(v, dict):
            for k, x in v.items():
                paths.append(at + [k])
                walk(x, at + [k])
        elif isinstance(v, list):
            for i, x in enumerate(v[:4]):
                paths.append(at + [i])
                walk(x, at + [i])

    walk(doc, [])
    if not paths:
        return raw
    where = rng.choice(paths)
    value = rng.choice([10**12, -1, 0, None, "../outside/victim.txt", str(outside / "victim.txt"),
                        "/dev/zero", [], {}, "x" * 64, 1e308, 2**31, "nan", True])
    node = doc
    for k in where[:-1]:
        node = node[k]
    node[where[-1]] = value
    return json.dumps(doc).encode()


def damage(path: pathlib.Path, op: str, rng: random.Random, outside: pathlib.Path) -> str:
    """Apply damage ``op`` to ``path``; returns a one-line description."""
    raw = path.read_bytes()
    n = len(raw)
    if op == "truncate":
        k = rng.randrange(0, max(n, 1))
        path.write_bytes(raw[:k])
        return f"truncated to {k} of {n} bytes"
    if op == "flip":
        b = bytearray(raw)
        spots = [rng.randrange(n) for _ in range(rng.randint(1, 16))] if n else []
        for s in spots:
            b[s] ^= 1 << rng.randrange(8)
        path.write_bytes(bytes(b))
        return f"{len(spots)} bit(s) flipped"
    if op == "garbage":   # a region replaced by finite float32 garbage (the corrupt-T case)
        if n < 16:
            return "too small"
        off = rng.randrange(n // 4, n)
        k = min(n - off, rng.choice([16, 4096, 1 << 20]))
        vals = np.float32(rng.uniform(0, 100)) * np.random.default_rng(rng.randrange(2**31)).random(
            k // 4 + 1, dtype=np.float32)
        b = bytearray(raw)
        b[off:off + k] = vals.tobytes()[:k]
        path.write_bytes(bytes(b))
        return f"{k} bytes at {off} replaced by finite garbage"
    if op == "nan":
        b = bytearray(raw)
        off = rng.randrange(n // 2, n) if n > 8 else 0
        k = min(n - off, 4096)
        b[off:off + k] = (np.full(k // 2 + 1, np.nan, np.float16).tobytes())[:k]
        path.write_bytes(bytes(b))
        return f"{k} bytes at {off} set to NaN"
    if op == "header":
        if path.suffix == ".npy":
            path.write_bytes(_npy_header_edit(raw, rng))
            return "NPY header edited"
        if path.suffix == ".json":
            path.write_bytes(_json_edit(raw, rng, outside))
            return "JSON value edited"
        path.write_bytes(raw[:8] + bytes(rng.randrange(256) for _ in range(56)) + raw[64:])
        return "first 64 bytes' tail randomised"
    if op == "append":
        path.write_bytes(raw + os.urandom(rng.choice([1, 100, 10000])))
        return "bytes appended"
    if op == "empty":
        path.write_bytes(b"")
        return "emptied"
    if op == "symlink-outside":
        path.unlink()
        path.symlink_to(outside / "victim.txt")
        return "replaced by a symlink to a file outside"
    if op == "symlink-zero":
        path.unlink()
        path.symlink_to("/dev/zero")
        return "replaced by a symlink to /dev/zero"
    if op == "fifo":
        path.unlink()
        os.mkfifo(path)
        return "replaced by a FIFO"
    raise ValueError(op)


OPS = ("truncate", "flip", "garbage", "nan", "header", "append", "empty", "symlink-outside",
       "symlink-zero", "fifo")


def plant(bk: pathlib.Path, rng: random.Random, outside: pathlib.Path) -> str:
    """A stage with a journal naming things inside and outside ``bk``, and maybe a symlinked
    chunk cache; returns a description."""
    from relightable_textures.lt_addon.io import atomic, transaction as tr

    names = [p.name for p in bk.iterdir()] or ["x"]
    pool = names + ["../outside/victim.txt", str(outside / "victim.txt"), "..", ".",
                    "../outside", "a/../../outside/victim.txt", "", "\x00", ".old"]
    stage_name = rng.choice([f"{tr.STAGE_PREFIX}{atomic.token()}".replace(f"-{os.getpid()}-", "-1-"),
                             f"{tr.STAGE_PREFIX}x.0-deadbeef.tmp",
                             f"{tr.STAGE_PREFIX}{atomic.token()}".replace(f"-{os.getpid()}-", "-0-")])
    stage = bk / stage_name
    if rng.random() < 0.15:
        stage.symlink_to(outside, target_is_directory=True)
        return f"stage {stage_name} is a symlink to outside/"
    stage.mkdir()
    (stage / ".old").mkdir()
    entries = rng.sample(pool, rng.randint(1, 4))
    for e in entries:
        if e and "/" not in e and "\x00" not in e and e not in (".", "..", ".old") and rng.random() < 0.5:
            (stage / e).write_bytes(b"planted")
        if e and "/" not in e and "\x00" not in e and e not in (".", "..", ".old") and rng.random() < 0.3:
            (stage / ".old" / e).write_bytes(b"planted old")
    journal = {"format": tr.FORMAT, "format_version": 1,
               "state": rng.choice(["swapping", "swapped", "committed", "staging", "bogus"]),
               "target": rng.choice([str(bk), str(outside), "/"]),
               "entries": entries, "retired": rng.sample(pool, rng.randint(0, 2)),
               "blend": rng.choice([None, str(outside / "victim.txt"), str(bk / "b.blend")]),
               "blend_before": None,
               "blend_tmp": rng.choice([None, str(outside / "victim.txt"),
                                        str(outside / f".victim.relight-vm-1-deadbeef.tmp.txt")]),
               "existed": rng.sample(pool, rng.randint(0, 2))}
    (stage / ".journal.json").write_text(json.dumps(journal))
    if rng.random() < 0.3:
        cache = bk / ".relight_cache"
        if not cache.exists():
            cache.symlink_to(outside, target_is_directory=True)
    return f"stage {stage_name} state {journal['state']} entries {entries!r}"


# ------------------------------------------------------------------------------------------
# one case

def snapshot(folder: pathlib.Path) -> dict:
    """Every entry under ``folder`` (not following links) with its kind and bytes' hash."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for n in dirs + files:
            p = os.path.join(root, n)
            st = os.lstat(p)
            h = None
            if os.path.isfile(p) and not os.path.islink(p):
                with open(p, "rb") as fh:
                    h = hashlib.sha256(fh.read()).hexdigest()
            out[os.path.relpath(p, folder)] = (st.st_mode, h)
    return out


def run_case(bakes: pathlib.Path, scratch: pathlib.Path, rng: random.Random,
             timeout: float) -> tuple:
    """(outcome, description): outcome in loaded / refused / failure."""
    from relightable_textures.lt_addon.errors import InputError
    from relightable_textures.lt_addon.io import transaction as tr

    if scratch.exists():
        shutil.rmtree(scratch)
    outside = scratch / "outside"
    outside.mkdir(parents=True)
    (outside / "victim.txt").write_bytes(b"the user's own file\n")
    (outside / "0123456789abcdef0123").mkdir()          # looks like a chunk-key folder
    (outside / "0123456789abcdef0123" / "keep.npy").write_bytes(b"keep")
    (outside / "empty").mkdir()
    before = snapshot(outside)
    kind = rng.choice(sorted(BAKES))
    bk = scratch / "bk"
    shutil.copytree(bakes / kind, bk, symlinks=True)
    entry = next(p for p in bk.iterdir() if p.name.endswith(ENTRY[kind]))
    if rng.random() < 0.1:   # a kept chunk of a resumed bake, damaged: rejected or reused whole
        from relightable_textures.lt_addon.io.chunk_cache import ChunkCache

        cache = ChunkCache(str(bk / ".relight_cache"), {"fuzz": 1})
        chunk = np.random.default_rng(rng.randrange(2**31)).random((64, 16), np.float32)
        cache.put("00000", chunk)
        files = sorted(p for p in pathlib.Path(cache.folder).iterdir() if p.is_file())
        target = rng.choice(files)
        what = f"chunk: {target.name} {damage(target, rng.choice(OPS), rng, outside)}"

        def action():
            got = ChunkCache(str(bk / ".relight_cache"), {"fuzz": 1}).get(
                "00000", shape=(64, 16), dtype=np.float32, lo=0.0, hi=1.0)
            if got is None:
                raise InputError("rejected: baked again")
            if not np.array_equal(got, chunk):
                raise AssertionError("a damaged chunk was reused")
    elif rng.random() < 0.2:
        what = "planted: " + plant(bk, rng, outside)
        action = lambda: tr.sweep(str(bk))   # noqa: E731
    else:
        files = sorted(p for p in bk.iterdir() if p.is_file() and (
            p.name.endswith(ENTRY[kind]) if kind != "texture" else not PREVIEW_ONLY.search(p.name)))
        target = rng.choice(files)
        op = rng.choice(OPS)
        what = f"{kind}: {target.name} {damage(target, op, rng, outside)}"
        action = lambda: load_and_use(kind, str(entry))   # noqa: E731

    def on_alarm(signum, frame):
        raise Hang()

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        action()
        outcome = "loaded"
    except Hang:
        outcome, what = "failure", what + f" -> ran past {timeout} s (a hang)"
    except InputError as exc:
        outcome = "refused"
        if "\n" in str(exc).strip():
            outcome, what = "failure", what + f" -> a refusal of several lines: {exc!r}"
    except MemoryError:
        outcome, what = "failure", what + " -> memory past the cap"
    except Exception as exc:
        outcome = "failure"
        what += " -> " + "".join(traceback.format_exception_only(type(exc), exc)).strip()
        what += "\n" + "".join(traceback.format_tb(exc.__traceback__)[-3:])
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    if len(what) > 1500:   # (zipfile quotes whole headers in its messages)
        what = what[:1500] + "..."
    after = snapshot(outside)
    if after != before:
        changed = sorted(set(after.items()) ^ set(before.items()))
        outcome, what = "failure", what + f" -> changed outside the folder: {changed[:4]}"
    return outcome, what


def fuzz(bakes: pathlib.Path, *, seconds: float | None, cases: int | None, seed: int,
         timeout: float, verbose: bool = False) -> dict:
    """Run cases drawn by Hypothesis until ``seconds`` or ``cases``; returns the counts."""
    from hypothesis import HealthCheck, given, settings, strategies as st

    scratch = pathlib.Path(tempfile.mkdtemp(prefix="relight-fuzz-"))
    counts = {"cases": 0, "loaded": 0, "refused": 0, "failure": 0, "failures": [],
              "by_kind": {}}
    seen: set = set()
    t0 = time.monotonic()

    def done():
        return ((seconds is not None and time.monotonic() - t0 >= seconds)
                or (cases is not None and counts["cases"] >= cases))

    @settings(max_examples=200, deadline=None, database=None, derandomize=False,
              suppress_health_check=list(HealthCheck))
    @given(st.integers(0, 2**63 - 1))
    def one(case_seed):
        if done() or case_seed in seen:   # (Hypothesis draws simple values again: run once)
            return
        seen.add(case_seed)
        outcome, what = run_case(bakes, scratch / "case", random.Random(case_seed), timeout)
        counts["cases"] += 1
        counts[outcome] += 1
        kind = what.split(":", 1)[0]
        row = counts["by_kind"].setdefault(kind, {"loaded": 0, "refused": 0, "failure": 0})
        row[outcome] += 1
        if outcome == "failure":
            counts["failures"].append({"seed": case_seed, "what": what})
            print(f"fuzz: FAILURE (case seed {case_seed}): {what}", file=sys.stderr, flush=True)
        elif verbose:
            print(f"fuzz: {outcome}: {what}", file=sys.stderr)

    from hypothesis import seed as hseed

    round_ = 0
    try:
        while not done():
            hseed(seed + round_)(one)()
            round_ += 1
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    counts["seconds"] = round(time.monotonic() - t0, 1)
    return counts


def replay(bakes: pathlib.Path, case_seed: int, timeout: float) -> None:
    scratch = pathlib.Path(tempfile.mkdtemp(prefix="relight-fuzz-replay-"))
    try:
        print(run_case(bakes, scratch / "case", random.Random(case_seed), timeout))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bakes", default=None, help="folder of the bakes (made there by the real "
                   "CLI when missing; default: a temporary folder)")
    p.add_argument("--seconds", type=float, default=None, help="run this long")
    p.add_argument("--cases", type=int, default=None, help="run this many cases")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--case-timeout", type=float, default=20.0)
    p.add_argument("--mem-cap-gib", type=float, default=4.0)
    p.add_argument("--json", default=None, help="write the counts and failures here")
    p.add_argument("--replay", type=int, default=None, help="run one case seed and print it")
    p.add_argument("--verbose", action="store_true")
    a = p.parse_args(argv)
    if a.seconds is None and a.cases is None and a.replay is None:
        a.cases = 200
    relight = str(pathlib.Path(sys.executable).parent / "relight")
    bakes = pathlib.Path(a.bakes) if a.bakes else pathlib.Path(tempfile.mkdtemp(prefix="relight-fuzz-bakes-"))
    make_bakes(bakes, relight)
    cap = int(a.mem_cap_gib * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (cap, resource.getrlimit(resource.RLIMIT_AS)[1]))
    if a.replay is not None:
        replay(bakes, a.replay, a.case_timeout)
        return 0
    counts = fuzz(bakes, seconds=a.seconds, cases=a.cases, seed=a.seed, timeout=a.case_timeout,
                  verbose=a.verbose)
    print(f"fuzz: {counts['cases']} cases in {counts['seconds']} s: {counts['loaded']} loaded, "
          f"{counts['refused']} refused, {counts['failure']} failed (memory cap "
          f"{a.mem_cap_gib:g} GiB, {a.case_timeout:g} s a case)")
    for kind, row in sorted(counts["by_kind"].items()):
        ok = {"planted": "swept (left alone or recovered inside)",
              "chunk": "reused whole"}.get(kind, "loaded")
        no = {"chunk": "rejected (baked again)"}.get(kind, "refused")
        print(f"fuzz:   {kind}: {row['loaded']} {ok}, {row['refused']} {no}, "
              f"{row['failure']} failed")
    if a.json:
        pathlib.Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        pathlib.Path(a.json).write_text(json.dumps(counts, indent=1))
    return 1 if counts["failure"] else 0


if __name__ == "__main__":
    sys.exit(main())
