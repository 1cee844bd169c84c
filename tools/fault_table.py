"""The fault table of docs/bake-files.md, measured: real bakes hit by each fault, and what the
user sees and what is on disk afterwards.

A good bake of the test-size bumps (16^2, 64 directions by Cycles calls, bounces on, one truth
light) is in ``bk/``; a second bake into it (``--force --seed 7``) meets each fault. For each:
the exit code, the line on stderr, whether the previous bake's files and the .blend are
byte-identical right after, and then after the next run's sweep, and what debris is left
before / after that next run. Prints Markdown.

Usage: ``.venv/bin/python tools/fault_table.py`` (about a minute on 2 cores).
"""

from __future__ import annotations

import os
import pathlib
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
BIN = pathlib.Path(sys.executable).parent / "relight"
STAGES = ("directions", "indirect", "fit", "write", "preview", "commit", "blend")


def args(blend, out, seed):
    return [str(BIN), "bake-textures", str(blend), "--object", "Bumps", "--preset", "draft",
            "--directions", "hemi:64", "--resolution", "16", "--direct", "cycles", "--truth",
            "1", "--truth-samples", "16", "--no-compare", "--seed", str(seed), "--out", str(out),
            "--force"]


def files(folder):
    return {p.name: p.read_bytes() for p in pathlib.Path(folder).iterdir() if p.is_file()}


DEBRIS = re.compile(r"relight-.+-\d+-[0-9a-f]{8}|\.relight-stage-")


def debris(folder):
    return sorted(n for _, d, f in os.walk(folder) for n in d + f if DEBRIS.search(n))


def line(stderr: str) -> str:
    ours = [ln for ln in stderr.splitlines() if ln.startswith("relight: ")]
    if not ours:
        return ""
    text = ours[-1]
    text = re.sub(r"/\S*/(bk|b\.blend)", r"\1", text)
    text = re.sub(r"\(details: \S+\)", "(details: <log>)", text)
    return text


def main() -> int:
    root = pathlib.Path(tempfile.mkdtemp(prefix="relight-faults-"))
    env0 = {k: v for k, v in os.environ.items() if k != "RELIGHT_FAULT"}
    r = subprocess.run([str(BIN), "scene", "bumps", "--out", str(root / "b.blend")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    r = subprocess.run(args(root / "b.blend", root / "bk", 1), capture_output=True, text=True,
                       env=env0)
    assert r.returncode == 0, r.stderr
    good = root / "good"
    good.mkdir()
    shutil.copytree(root / "bk", good / "bk")
    shutil.copyfile(root / "b.blend", good / "b.blend")

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (24 * 1024, 24 * 1024))

    cases = [(f"killed (SIGKILL) at {s}", s, {"RELIGHT_FAULT": f"{s}:kill"}, None) for s in STAGES]
    cases += [(f"exception at {s}", s, {"RELIGHT_FAULT": f"{s}:raise"}, None) for s in STAGES]
    cases += [("disk full (RLIMIT_FSIZE 24 KiB, EFBIG)", "directions (T's store)", {}, limit),
              ("permission denied (injected EACCES; tests run as root)", "write", {"RELIGHT_FAULT": "write:eacces"}, None),
              ("disk full (injected ENOSPC)", "write", {"RELIGHT_FAULT": "write:enospc"}, None),
              ("a folder where the report goes", "commit (check)", {}, "folder"),
              ("NaN in a kept chunk", "directions (reuse)", {}, "nan"),
              ("truncated kept chunk", "directions (reuse)", {}, "truncated")]
    rows = []
    for name, stage, env, how in cases:
        work = root / re.sub(r"\W+", "_", name)
        shutil.copytree(good, work)
        blend, bk = work / "b.blend", work / "bk"
        if how == "folder":
            (bk / "Bumps_texture_report.json").unlink()
            (bk / "Bumps_texture_report.json").mkdir()
        if how in ("nan", "truncated"):
            subprocess.run(args(blend, bk, 7), env=dict(env0, RELIGHT_FAULT="directions:kill"),
                           capture_output=True)
            import numpy as np

            chunk = next(bk.glob(".relight_cache/Bumps/*/direct_00000.npy"))
            if how == "nan":
                a = np.load(chunk)
                a[0, 0, :7] = np.nan
                np.save(chunk, a)
            else:
                data = chunk.read_bytes()
                chunk.write_bytes(data[: len(data) // 2])
        before, blend_before = files(bk), blend.read_bytes()
        t0 = time.perf_counter()
        r = subprocess.run(args(blend, bk, 7), env=dict(env0, **env), capture_output=True,
                           text=True, preexec_fn=how if callable(how) else None)
        seconds = time.perf_counter() - t0
        import json

        rep = json.loads((bk / "Bumps_texture_report.json").read_text()) \
            if (bk / "Bumps_texture_report.json").is_file() else {}
        journals = [json.loads(j.read_text())["state"] for j in bk.glob(".relight-stage-*/.journal.json")]
        if r.returncode == 0:
            state = "replaced by the new bake (it succeeded)"
        elif "swapping" in journals:
            state = "half-swapped, journal `swapping`: the next run's sweep undoes it"
        elif files(bk) == before and blend.read_bytes() == blend_before:
            state = "byte-identical"
        else:
            state = "CHANGED"
        seen = line(r.stderr) if r.returncode else next(
            (ln.strip() for ln in r.stdout.splitlines() if "failed their check" in ln), "")
        left = debris(work)
        r2 = subprocess.run(args(blend, bk, 7), env=env0, capture_output=True, text=True)
        after = debris(work)
        rows.append((name, stage, r.returncode, seen, state, len(left),
                     r2.returncode, len(after), rep.get("chunks_rejected", "-"), seconds))
        shutil.rmtree(work)
    print(f"Measured {time.strftime('%Y-%m-%d')} on {os.cpu_count()} cores, "
          f"`python tools/fault_table.py`.\n")
    print("| fault | stage | exit | what the user sees | previous bake and .blend right after | "
          "debris right after | chunks rejected | next run: exit, debris |")
    print("|---|---|---|---|---|---|---|---|")
    for (name, stage, rc, text, state, left, rc2, after, rej, sec) in rows:
        print(f"| {name} | {stage} | {rc} | {f'`{text}`' if text else '-'} | {state} | {left} | "
              f"{rej if rc == 0 else '-'} | {rc2}, {after} |")
    shutil.rmtree(root)
    return 0


if __name__ == "__main__":
    sys.exit(main())
