"""Install the built linux-x64 zip into every supported Blender (the PyPI ``bpy`` releases) and
bake through the installed operator; run the full test suite on the newest bpy and the
version-sensitive subset on 5.2 LTS (both Python 3.13; ``make test`` runs the full suite on 5.0.1).

For each Blender in :data:`MATRIX` a venv holding only ``bpy`` (and what its wheel requires:
numpy, ...) -- never scipy, OpenEXR or embreex, so the zip's bundled wheels must do their job -- runs
:data:`CHECK` in a fresh temporary ``BLENDER_USER_RESOURCES``: install the zip through
``bpy.ops.extensions.package_install_files``, check that the add-on is enabled and its operators
registered, that scipy, OpenEXR and embreex import from the extension's own site-packages, and bake a
tiny texture through ``bpy.ops.relight.bake_textures``. A Blender that must refuse the zip
(4.2.0: no Python-tag wheel filter, below ``blender_version_min``) must refuse it.
Then a second venv per suite version (scipy, OpenEXR, pytest, ... plus this package through
``pip install -e``, the pyproject mapping) runs the whole suite on :data:`NEWEST` and the tests
marked ``version_sensitive`` on 5.2 LTS (why that subset is enough: docs/testing.md).

Venvs live under ``--cache`` (default ``~/.cache/relightable-textures/blender-matrix``) and are
reused when their stamp matches; pip's own cache keeps the downloaded wheels. Prints each
phase's seconds and one table row per Blender, and exits 1 if any row differs from what is
expected. ``--deadline`` (a Unix time, from ``.ci/run``) bounds every step: a step that would
run past it is stopped and the run fails with one line saying which.

Usage: ``python3 tools/blender_matrix.py [--zip dist/<id>-<version>-linux_x64.zip]
[--only VERSION ...] [--suite VERSION ...|none] [--subset VERSION ...|none] [--deadline T]
[--markdown FILE]`` (``make matrix`` builds the zips first).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: (bpy version, Python, expected to install). 4.2.13 is the oldest 4.2 LTS on PyPI with
#: Blender's Python-tag wheel filter (blender_version_min); 4.2.0 must refuse the zip.
MATRIX = [
    ("4.2.0", "3.11", False),
    ("4.2.13", "3.11", True),
    ("4.5.15", "3.11", True),
    ("5.0.1", "3.11", True),
    ("5.2.3", "3.13", True),
    ("5.3.0", "3.13", True),
]
NEWEST = MATRIX[-1][0]
#: Where CI runs the full suite besides ``make test`` (5.0.1, Python 3.11): the newest bpy on
#: PyPI (Python 3.13, numpy 2).
SUITE_DEFAULT = [NEWEST]
#: Where CI runs only the tests marked ``version_sensitive`` (``pytest -m version_sensitive``):
#: 5.2 LTS, which shares Python 3.13, numpy 2 and every branch of operators/base/compat.py with the
#: newest bpy (docs/testing.md says why that subset is enough).
SUBSET_DEFAULT = ["5.2.3"]
#: The pytest marker of that subset (declared in pyproject.toml).
SUBSET_MARKER = "version_sensitive"

#: Failures of the full suite on Python 3.13 Blenders that are known and not fixed yet: none
#: since 2026-11-28 (the ten listed before were fixed: the CLI's stdout, a 5.2 reference bake,
#: two float tolerances, zero-area faces). Any failure not listed fails the matrix, and so does
#: a listed one that passes again.
KNOWN_313_FAILURES: set = set()


def judge_suite(stdout: str) -> tuple[bool, list[str]]:
    """(ok, problems): ok when pytest ran tests and failed exactly the known 3.13 failures."""
    failed = {m.group(1) for m in re.finditer(r"^(?:FAILED|ERROR) (\S+)", stdout, re.M)}
    problems = [f"new failure: {t}" for t in sorted(failed - KNOWN_313_FAILURES)]
    problems += [f"known failure now passes (remove it from KNOWN_313_FAILURES): {t}"
                 for t in sorted(KNOWN_313_FAILURES - failed)]
    if not re.search(r"\d+ passed", stdout):
        problems.append("pytest ran no test")
    return not problems, problems

#: Extra packages of the full-suite venv (bpy brings numpy; scipy/OpenEXR as in the zip).
SUITE_PACKAGES = ["scipy==1.17.1", "OpenEXR==3.5.3", "embreex==4.4.0.post1", "pytest==9.2.0",
                  "hypothesis==6.170.17",
                  "matplotlib==3.11.2", "dask==2026.8.0", "distributed==2026.8.0",
                  "setuptools==84.2.1"]

CHECK = r'''
import json, os, platform, sys, traceback
zip_path, work = sys.argv[1], sys.argv[2]
rep = {"python": platform.python_version()}
def out():
    print("MATRIX " + json.dumps(rep), flush=True)
try:
    import importlib.util
    rep["clean_venv"] = not any(importlib.util.find_spec(m)
                                for m in ("scipy", "OpenEXR", "embreex"))
    import bpy
    rep["blender"] = bpy.app.version_string
    user = os.environ["BLENDER_USER_RESOURCES"]
    site = os.path.join(user, "extensions", ".local", "lib",
                        "python%d.%d" % sys.version_info[:2], "site-packages")
    mod = "bl_ext.user_default.relightable_textures"
    try:
        rep["install"] = sorted(bpy.ops.extensions.package_install_files(
            filepath=zip_path, repo="user_default", enable_on_install=True))
    except Exception as ex:  # a refused install reports an error: keep its first line
        rep["install"] = "refused: " + str(ex).strip().splitlines()[0][:200]
    rep["installs"] = rep["install"] == ["FINISHED"] and os.path.isfile(
        os.path.join(user, "extensions", "user_default", "relightable_textures",
                     "blender_manifest.toml"))
    ops = [n for n in dir(bpy.ops.relight) if not n.startswith("_")]
    rep["enables"] = (mod in bpy.context.preferences.addons and "bake_textures" in ops
                      and "RELIGHT_OT_bake_textures" in dir(bpy.types))
    if rep["enables"]:
        import scipy, scipy.linalg, OpenEXR, embreex
        rep["wheels_from"] = {m.__name__: m.__file__ for m in (scipy, OpenEXR, embreex)}
        rep["wheels"] = all(f.startswith(site) for f in rep["wheels_from"].values())
        bpy.ops.relight.add_sample_scene(name="bumps", size="test")
        props = bpy.context.scene.relight
        props.preset = "draft"
        # the default method (transport): 24 hard suns at 16^2, the indirect light gathered by
        # rays (the draft preset's 2 bounces) with its own node group
        props.directions, props.resolution, props.indirect_samples = 24, 16, 4
        props.output_dir = os.path.join(work, "bake") + os.sep
        bpy.context.view_layer.objects.active = bpy.data.objects["Bumps"]
        rep["bake_result"] = sorted(bpy.ops.relight.bake_textures())
        files = sorted(os.listdir(props.output_dir)) if os.path.isdir(props.output_dir) else []
        rep["bake_files"] = files
        rep["bake"] = (rep["bake_result"] == ["FINISHED"] and props.method == "transport"
                       and {"Bumps_texture_report.json", "Bumps_transport_texture.npy",
                            "Bumps_preview_tables.exr"} <= set(files))
        if rep["bake"]:
            with open(os.path.join(props.output_dir, "Bumps_texture_report.json")) as fh:
                bake_rep = json.load(fh)
            # auto shows T's sparse tables or the horizon map, whichever its held-out check
            # found closer to the rays (24 directions: the horizons); each has its own images,
            # and its group is built with this Blender's nodes
            shown = bake_rep["preview"]["viewport"]
            rep["viewport"] = shown
            images = {"transport": {"Bumps_preview_transport.png",
                                    "Bumps_preview_sparse_index.exr"},
                      "horizon": {"Bumps_horizons.npz", "Bumps_preview_horizons.png",
                                  "Bumps_preview_normals.exr"}}.get(shown)
            group = bpy.data.node_groups.get("Relight Transport (Bumps)")
            indirect = bpy.data.node_groups.get("Relight Transport indirect (Bumps)")
            rep["indirect"] = bake_rep.get("indirect", {}).get("method")
            rep["directions"] = bake_rep["directions"]
            rep["direction_set"] = bake_rep["direct"].get("direction_set")
            # 24 hard suns and the band mirrored under the horizon (its own count)
            under = (rep["direction_set"] or {}).get("under_horizon", {}).get("directions", -1)
            rep["bake"] = (bake_rep["directions"] == 24 + under and under > 0
                           and bake_rep["direct"]["engine"] == "rays"
                           and images is not None and images <= set(files)
                           and group is not None and group.get("relight_viewport") == shown
                           and rep["indirect"] == "gathered" and indirect is not None
                           and indirect.get("relight_indirect") == "gathered"
                           and "Bumps_indirect.npz" in files)
except Exception:
    rep["error"] = traceback.format_exc()[-1500:]
out()
'''


def find_python(version: str) -> str:
    """An interpreter of ``version``: pyenv's, else ``python3.13`` on PATH (not a pyenv shim,
    which fails for a version that is installed but not selected)."""
    candidates = []
    pyenv = os.path.expanduser("~/.pyenv/versions")
    if os.path.isdir(pyenv):
        candidates += [os.path.join(pyenv, d, "bin", "python3") for d in sorted(os.listdir(pyenv))
                       if d.startswith(version + ".")]
    candidates.append(shutil.which(f"python{version}") or "")
    for c in candidates:
        if c and os.path.exists(c) and "/shims/" not in c:
            return c
    raise SystemExit(f"blender_matrix: no Python {version} found (python{version} or pyenv)")


def ensure_venv(path: str, python: str, packages: list[str]) -> str:
    """A venv at ``path`` with exactly ``packages`` installed by pip; reused while its stamp
    (the package list) matches. Returns its python."""
    stamp = os.path.join(path, ".matrix-stamp")
    want = json.dumps(packages)
    exe = os.path.join(path, "bin", "python")
    if os.path.exists(stamp) and open(stamp).read() == want and os.path.exists(exe):
        return exe
    t0 = time.time()
    shutil.rmtree(path, ignore_errors=True)
    subprocess.run([python, "-m", "venv", path], check=True)
    subprocess.run([exe, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                    *packages], check=True)
    with open(stamp, "w") as fh:
        fh.write(want)
    print(f"blender_matrix: created the venv {os.path.basename(path)} in {time.time() - t0:.0f} s "
          "(a warm run reuses it)", flush=True)
    return exe


def check_version(cache: str, bpy_version: str, python: str, zip_path: str) -> dict:
    t0 = time.time()
    exe = ensure_venv(os.path.join(cache, f"bpy-{bpy_version}"), find_python(python),
                      [f"bpy=={bpy_version}"])
    t1 = time.time()
    with tempfile.TemporaryDirectory(prefix=f"relight-matrix-{bpy_version}-") as work:
        user = os.path.join(work, "blender-user")
        os.makedirs(user)
        env = dict(os.environ, BLENDER_USER_RESOURCES=user)
        r = subprocess.run([exe, "-c", CHECK, zip_path, work], capture_output=True, text=True,
                           env=env, cwd=work, timeout=900)
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("MATRIX ")]
    rep = json.loads(lines[-1][len("MATRIX "):]) if lines else {
        "error": f"exit {r.returncode}: " + (r.stdout[-800:] + r.stderr[-800:])}
    # Blender prints why it refused a package (e.g. "ERROR relightable_textures: This Blender
    # version (4.2.0) doesn't meet the minimum supported version (4.2.13)") and still returns
    # FINISHED; keep those lines.
    rep["messages"] = [ln.strip() for ln in r.stdout.splitlines()
                       if ln.startswith("ERROR ") or "should have been installed" in ln]
    rep["setup_s"], rep["run_s"] = round(t1 - t0, 1), round(time.time() - t1, 1)
    return rep


class DeadlineError(RuntimeError):
    """A step would run past ``--deadline``."""


def remaining(deadline: float | None, step: str) -> float | None:
    """Seconds left before ``deadline`` for ``step`` (None: no deadline); raises when none."""
    if deadline is None:
        return None
    left = deadline - time.time()
    if left <= 0:
        raise DeadlineError(f"no time left for {step} before the deadline")
    return left


def run_suite(cache: str, bpy_version: str, python: str, log_dir: str,
              marker: str | None = None, deadline: float | None = None) -> tuple[bool, str]:
    """The pytest suite (only the tests marked ``marker`` if given) in a venv of
    ``bpy_version``; returns (passed, pytest's summary). The whole output goes to
    ``log_dir/suite-<version>.log``; the 30 slowest tests and the failures are printed here."""
    what = f"the {marker} subset" if marker else "the full suite"
    exe = ensure_venv(os.path.join(cache, f"suite-{bpy_version}"), find_python(python),
                      [f"bpy=={bpy_version}", *SUITE_PACKAGES])
    # The checkout may move between runs (CI clones afresh): re-point the editable install.
    # setuptools is in the venv, so no isolated build environment is fetched for it.
    subprocess.run([exe, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                    "--no-deps", "--no-build-isolation", "--no-index", "-e", ROOT], check=True,
                   capture_output=True)
    cmd = [exe, "-m", "pytest", "-q", "-rfE", "-p", "no:cacheprovider", "--durations=30"]
    if marker:
        cmd += ["-m", marker]
    try:
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                           timeout=remaining(deadline, f"{what} on bpy {bpy_version}"))
    except subprocess.TimeoutExpired as exc:
        raise DeadlineError(f"{what} on bpy {bpy_version} was still running at the deadline "
                            f"(after {exc.timeout:.0f} s)") from None
    os.makedirs(log_dir, exist_ok=True)
    log = os.path.join(log_dir, f"suite-{bpy_version}.log")
    with open(log, "w") as fh:
        fh.write(r.stdout + r.stderr)
    lines = r.stdout.splitlines()
    start = next((i for i, ln in enumerate(lines) if "slowest 30 durations" in ln
                  or "short test summary info" in ln), max(len(lines) - 5, 0))
    print(f"blender_matrix: {what} on bpy {bpy_version} (whole output: {log})")
    print("\n".join(lines[start:]))
    ok, problems = judge_suite(r.stdout)
    for problem in problems:
        print(f"blender_matrix: bpy {bpy_version}: {problem}")
    if not ok:
        sys.stderr.write(r.stderr[-2000:])
    summary = next((ln.strip("= ") for ln in reversed(r.stdout.splitlines())
                    if re.search(r"\d+ (passed|failed|error)", ln)), "no pytest summary")
    summary = re.sub(r" in [0-9.]+s.*$", "", summary)
    if r.returncode != 0 and ok:
        summary += f" (the {len(KNOWN_313_FAILURES)} known 3.13 failures)"
    return ok, ("" if marker is None else f"{marker} subset: ") + summary


def default_zip() -> str:
    import tomllib

    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as fh:
        m = tomllib.load(fh)
    return os.path.join(ROOT, "dist", f"{m['id']}-{m['version']}-linux_x64.zip")


def yes(flag) -> str:
    return "yes" if flag else "**no**"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--zip", default=default_zip(),
                        help="the linux-x64 extension zip (default: the one `make dist` built)")
    parser.add_argument("--cache", default=os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")),
        "relightable-textures", "blender-matrix"))
    parser.add_argument("--only", action="append", default=[],
                        help="check only this bpy version (repeatable; 'none' for no row)")
    parser.add_argument("--suite", action="append", default=None,
                        help=f"run the full suite on this bpy version (default {', '.join(SUITE_DEFAULT)}; "
                             "'none' for no full suite)")
    parser.add_argument("--subset", action="append", default=None,
                        help=f"run the {SUBSET_MARKER} tests on this bpy version (default "
                             f"{', '.join(SUBSET_DEFAULT)}; 'none' for no subset)")
    parser.add_argument("--deadline", type=float, default=None,
                        help="a Unix time: a step still running then is stopped and the run fails")
    parser.add_argument("--markdown", help="also write the table to this file")
    parser.add_argument("--log-dir", default=os.path.join(ROOT, "dist"),
                        help="where the suites' output is written")
    args = parser.parse_args()
    if not os.path.isfile(args.zip) or not args.zip.endswith(".zip"):
        print(f"blender_matrix: error: --zip {args.zip!r} is not a zip file (run `make dist`)",
              file=sys.stderr)
        return 2
    zip_path = os.path.abspath(args.zip)
    known = {v: (py, ok) for v, py, ok in MATRIX}
    suites = list(SUITE_DEFAULT) if args.suite is None else [s for s in args.suite if s != "none"]
    subsets = (list(SUBSET_DEFAULT) if args.subset is None
               else [s for s in args.subset if s != "none"])
    for v in [o for o in args.only if o != "none"] + suites + subsets:
        if v not in known:
            print(f"blender_matrix: error: bpy {v} is not in the matrix ({', '.join(known)})",
                  file=sys.stderr)
            return 2
    os.makedirs(args.cache, exist_ok=True)
    failures, reps, suite_cells = [], {}, {}
    try:
        t0 = time.time()
        for version, python, _ in MATRIX:
            if args.only and version not in args.only:
                continue
            remaining(args.deadline, f"the install row of bpy {version}")
            reps[version] = rep = check_version(args.cache, version, python, zip_path)
            print(f"blender_matrix: bpy {version}: {json.dumps(rep)}", flush=True)
        print(f"blender_matrix: phase install rows ({len(reps)} Blenders) took "
              f"{time.time() - t0:.0f} s", flush=True)
        for version, marker in [(v, None) for v in suites] + [(v, SUBSET_MARKER) for v in subsets]:
            t1 = time.time()
            passed, summary = run_suite(args.cache, version, known[version][0], args.log_dir,
                                        marker, args.deadline)
            suite_cells[version] = summary if passed else f"**{summary}**"
            if not passed:
                failures.append(f"{version}: {summary}")
            print(f"blender_matrix: phase {'subset' if marker else 'full suite'} on bpy {version} "
                  f"took {time.time() - t1:.0f} s", flush=True)
    except DeadlineError as exc:
        print(f"blender_matrix: error: {exc}; the run would pass its time budget "
              "(the slowest tests: docs/testing.md)", file=sys.stderr)
        return 1
    rows = ["| Blender (bpy) | Python | installs | enables | bundled scipy / OpenEXR import "
            "| tiny bake (installed operator) | suite |", "|---|---|---|---|---|---|---|"]
    for version, python, expect_install in MATRIX:
        if version not in reps:
            continue
        rep = reps[version]
        if "error" in rep:
            failures.append(f"{version}: {rep['error']}")
        if not rep.get("clean_venv"):
            failures.append(f"{version}: the venv has its own scipy/OpenEXR")
        if expect_install:
            ok = all(rep.get(k) for k in ("installs", "enables", "wheels", "bake"))
            if not ok:
                failures.append(f"{version}: " + ", ".join(
                    f"{k}={rep.get(k)}" for k in ("install", "enables", "wheels", "bake"))
                    + (f" (viewport {rep.get('viewport')}, files {rep.get('bake_files')})"
                       if not rep.get("bake") else ""))
            bake_cell = yes(rep.get("bake"))
            if rep.get("bake") and rep.get("viewport"):
                bake_cell += f" ({rep['viewport']} viewport)"
            row = [yes(rep.get("installs")), yes(rep.get("enables")), yes(rep.get("wheels")),
                   bake_cell]
        else:
            refused = not rep.get("installs") and not rep.get("enables")
            if not refused:
                failures.append(f"{version}: installed a zip it must refuse: {rep.get('install')}")
            msg = (rep["messages"] or [str(rep.get("install", ""))])[0]
            row = [f"refused, as it must ({msg.replace('|', '/')})" if refused else "**yes**",
                   "-", "-", "-"]
        rows.append(f"| {rep.get('blender', version)} (bpy {version}) | "
                    f"{rep.get('python', python)} | " + " | ".join(row)
                    + f" | {suite_cells.get(version, 'not run')} |")
    table = "\n".join(rows)
    print("\n" + table)
    if args.markdown:
        with open(args.markdown, "w") as fh:
            fh.write(table + "\n")
    if failures:
        print("\nblender_matrix: FAILED\n  " + "\n  ".join(failures), file=sys.stderr)
        return 1
    print("blender_matrix: every Blender behaved as expected")
    return 0


if __name__ == "__main__":
    sys.exit(main())
