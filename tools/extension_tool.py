"""Build and validate the extension zips, one per platform, with Blender's own extension tool.

Blender's extension tool (``blender_ext.py``, what ``blender --command extension`` runs) is used
rather than re-implemented. It needs plain Python >= 3.11 and is found, in this order:

1. ``--blender PATH`` (Blender 4.2 or later; ``make dist BLENDER=PATH``): the tool inside that
   install (``<version>/scripts/addons_core/bl_pkg/cli/blender_ext.py`` next to the executable
   on Linux and Windows, ``Blender.app/Contents/Resources/<version>/...`` on macOS,
   ``/usr/share/blender/<version>/...`` for a Linux distribution's package), else
   ``PATH --factory-startup --command extension ...`` itself;
2. the ``bpy`` module of the Python running this script (the development venv, or a venv
   holding only bpy), which ships the same tool (``bpy/<version>/scripts/...``);
3. the pinned bpy wheel (requirements.txt) in the wheelhouse ``make venv`` shares
   (``--wheelhouse``), downloaded there once (~360 MB) if missing: only the tool and Blender's
   list of valid tags are read out of it; nothing is installed.

The tags are validated against Blender's own list (``scripts/modules/_bpy_internal/extensions/
tags.py``), as ``blender --command extension`` does. The wheels the manifest lists (SciPy,
OpenEXR and embreex for CPython 3.11 and 3.13 on every platform in ``platforms``, and tzdata,
the IANA time-zone database that :mod:`zoneinfo` reads where the system has none, as on
Windows: one pure-Python ``py2.py3-none-any`` wheel for every platform and Python) are
downloaded first with this Python's pip, pinned in requirements-wheels.txt. ``build
--split-platforms`` then writes one zip per platform holding only that platform's wheels and
the platform-independent ones (Blender's tool keeps a wheel whose platform tag is ``any`` in
every platform's zip); each zip is validated by the tool and checked here against the manifest.

Usage: ``python tools/extension_tool.py [--output-dir DIR] [--blender PATH] [--wheelhouse DIR]``
prints the built zips, one a line, as ``<blender platform> <path>``; which tool built them goes
to stderr.
"""

from __future__ import annotations

import argparse
import glob
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile

if sys.version_info < (3, 11):   # Blender's extension tool and this script read TOML
    raise SystemExit(f"extension_tool: needs Python 3.11 or later, not "
                     f"{sys.version.split()[0]} ({sys.executable})")

import tomllib  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: The Python versions of the supported Blenders (4.2 LTS-5.0: 3.11; 5.1 and later: 3.13).
PYTHONS = ("3.11", "3.13")

#: Blender platform -> pip ``--platform`` tags that select its wheels (pip also accepts older
#: macOS versions than the one named, so each pair yields exactly one wheel per package).
PIP_PLATFORMS = {
    "linux-x64": ("manylinux_2_28_x86_64",),
    "windows-x64": ("win_amd64",),
    "macos-arm64": ("macosx_14_0_arm64",),
    "macos-x64": ("macosx_10_15_x86_64",),
}
#: Packages whose wheels need a newer platform than :data:`PIP_PLATFORMS` names (embreex 4.4
#: is built for macOS 13 on Intel Macs), downloaded with these tags instead.
NEWER_PLATFORMS = {"embreex": {"macos-x64": ("macosx_13_0_x86_64",)}}


def requirements() -> list[str]:
    """The pinned lines of requirements-wheels.txt."""
    with open(os.path.join(ROOT, "requirements-wheels.txt")) as fh:
        return [ln.split("#")[0].strip() for ln in fh if ln.split("#")[0].strip()]


#: Blender's extension tool and its list of valid tags inside a ``<version>/`` folder of a
#: Blender install or of the bpy module.
EXT_TOOL = ("scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py")
VALID_TAGS = ("scripts", "modules", "_bpy_internal", "extensions", "tags.py")

#: Where a Blender install keeps its ``<version>/`` folder, relative to the folder of its
#: executable: next to it (blender.org's Linux archive, Windows zip and installer, Steam,
#: snap), ``Blender.app/Contents/Resources/`` on macOS (the executable is
#: ``Contents/MacOS/Blender``), ``/usr/share/blender/`` for a Linux distribution's package
#: (the executable is ``/usr/bin/blender``). Blender's manual, "Blender's Directory Layout".
BLENDER_LAYOUTS = (".", os.path.join("..", "Resources"), os.path.join("..", "share", "blender"))

#: Where ``make venv`` keeps the pinned wheels of requirements.txt (the Makefile's WHEELHOUSE),
#: the bpy wheel among them.
WHEELHOUSE = os.path.join(os.path.expanduser("~"), ".cache", "relightable-textures", "wheelhouse")


class ExtTool:
    """One way of running Blender's extension tool: ``command`` + a subcommand + arguments."""

    def __init__(self, command: list[str], tags: str | None, origin: str):
        self.command, self.tags, self.origin = command, tags, origin

    def run(self, subcommand: str, *args: str) -> None:
        cmd = [*self.command, subcommand]
        if self.tags is not None:
            cmd.append(f"--valid-tags={self.tags}")
        try:
            subprocess.run(cmd + list(args), check=True, stdout=sys.stderr)
        except (OSError, subprocess.CalledProcessError) as exc:
            why = (f"exit status {exc.returncode}"
                   if isinstance(exc, subprocess.CalledProcessError) else str(exc))
            hint = (" (the extension command needs Blender 4.2 or later)"
                    if "--command" in self.command else "")
            raise SystemExit(f"extension_tool: {subcommand} with {self.origin} failed: "
                             f"{why}{hint}") from None


def _version_folder(base: str) -> str | None:
    """The newest ``<major>.<minor>`` folder under ``base`` that holds the extension tool."""
    try:
        names = os.listdir(base)
    except OSError:
        return None
    found = sorted((tuple(int(x) for x in n.split(".")), n) for n in names
                   if re.fullmatch(r"\d+\.\d+", n)
                   and os.path.isfile(os.path.join(base, n, *EXT_TOOL)))
    return os.path.join(base, found[-1][1]) if found else None


def _tool_in(version_folder: str, origin: str) -> ExtTool:
    tags = os.path.join(version_folder, *VALID_TAGS)
    return ExtTool([sys.executable, os.path.join(version_folder, *EXT_TOOL)],
                   tags if os.path.isfile(tags) else None, origin)


def blender_tool(blender: str) -> ExtTool:
    """The extension tool of the Blender install whose executable (or macOS ``Blender.app``)
    is ``blender``, run with this Python; where the install's layout is none of
    :data:`BLENDER_LAYOUTS`, that Blender's own ``--command extension``."""
    exe = blender
    if os.path.isdir(exe) and os.path.basename(os.path.normpath(exe)).endswith(".app"):
        exe = os.path.join(exe, "Contents", "MacOS", "Blender")
    if not os.path.isfile(exe):
        found = shutil.which(exe)
        if not found:
            raise SystemExit(f"extension_tool: --blender {blender!r}: no such file or command")
        exe = found
    # a link on the PATH (/usr/local/bin/blender -> /opt/blender-5.0/blender): both folders
    for folder in dict.fromkeys((os.path.dirname(os.path.abspath(exe)),
                                 os.path.dirname(os.path.realpath(exe)))):
        for rel in BLENDER_LAYOUTS:
            found = _version_folder(os.path.normpath(os.path.join(folder, rel)))
            if found:
                return _tool_in(found, f"the Blender install at {found}")
    return ExtTool([exe, "--factory-startup", "--command", "extension"], None,
                   f"{exe} --command extension")


def bpy_tool() -> ExtTool | None:
    """The extension tool inside this Python's bpy module (bpy is not imported), or None."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return None
    base = list(spec.submodule_search_locations)[0]
    found = _version_folder(base)
    if found is None:
        raise SystemExit(f"extension_tool: blender_ext.py not found under {base}")
    return _tool_in(found, f"the bpy module at {found}")


def pinned_bpy() -> str:
    """The bpy version requirements.txt pins (the development venv's)."""
    with open(os.path.join(ROOT, "requirements.txt")) as fh:
        for line in fh:
            m = re.fullmatch(r"bpy==([\w.]+)", line.split("#")[0].strip())
            if m:
                return m.group(1)
    raise SystemExit("extension_tool: requirements.txt pins no bpy version")


def _require_pip(why: str) -> None:
    if importlib.util.find_spec("pip") is None:
        raise SystemExit(f"extension_tool: {sys.executable} has no pip, needed to {why} "
                         "(`python -m ensurepip --user`, or the system's python3-pip)")


def wheel_tool(wheelhouse: str, workdir: str) -> ExtTool:
    """The extension tool read out of the pinned bpy wheel in ``wheelhouse`` (downloaded there
    first if missing) into ``workdir``; bpy itself is not installed."""
    version = pinned_bpy()
    wheels = sorted(glob.glob(os.path.join(glob.escape(wheelhouse), f"bpy-{version}-*.whl")))
    if not wheels:
        _require_pip("download the bpy wheel")
        print(f"extension_tool: no Blender given (make dist BLENDER=/path/to/blender) and no "
              f"bpy module: downloading the bpy {version} wheel (~360 MB, once) into "
              f"{wheelhouse} for Blender's extension tool inside it", file=sys.stderr)
        # bpy is built for one CPython version per release (requirements.txt: 3.11 for 5.0);
        # the tool inside is plain Python, the same in every platform's wheel
        subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                        "--only-binary=:all:", "--python-version", PYTHONS[0],
                        "--implementation", "cp", "--platform", PIP_PLATFORMS["linux-x64"][0],
                        "-d", wheelhouse, f"bpy=={version}"], check=True)
        wheels = sorted(glob.glob(os.path.join(glob.escape(wheelhouse), f"bpy-{version}-*.whl")))
        if not wheels:
            raise SystemExit(f"extension_tool: pip wrote no bpy-{version} wheel to {wheelhouse}")
    with zipfile.ZipFile(wheels[-1]) as whl:
        wanted = [n for n in whl.namelist()
                  if re.fullmatch(r"bpy/\d+\.\d+/" + "(%s|%s)" % ("/".join(EXT_TOOL),
                                                                  "/".join(VALID_TAGS)), n)]
        for name in wanted:
            dst = os.path.join(workdir, *name.split("/"))
            os.makedirs(os.path.dirname(dst), exist_ok=True)
            with whl.open(name) as src, open(dst, "wb") as out:
                shutil.copyfileobj(src, out)
    found = _version_folder(os.path.join(workdir, "bpy"))
    if found is None:
        raise SystemExit(f"extension_tool: no blender_ext.py in {wheels[-1]}")
    return _tool_in(found, f"the bpy {version} wheel {wheels[-1]}")


def extension_tool(blender: str | None, wheelhouse: str, workdir: str) -> ExtTool:
    """Blender's extension tool, found in the order the module's docstring gives."""
    tool = blender_tool(blender) if blender else bpy_tool()
    return tool or wheel_tool(wheelhouse, workdir)


def manifest() -> dict:
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as fh:
        return tomllib.load(fh)


def wheel_package(name: str) -> str:
    """The normalised project name of a wheel file name or a requirement line
    (``embreex-4.4.0.post1-cp311-...whl``, ``openexr==3.5.3``): lower case, runs of ``-_.``
    as one ``-`` (PEP 503)."""
    base = os.path.basename(name)
    project = base.split("-")[0] if base.endswith(".whl") else re.split(r"[=<>!~;\[ ]", base)[0]
    return re.sub(r"[-_.]+", "-", project.strip()).lower()


def is_pure(name: str) -> bool:
    """Whether a wheel file name is platform-independent (platform tag ``any``, as tzdata's
    ``py2.py3-none-any``): one file serves every platform and Python, and Blender's tool puts
    it in every platform's zip."""
    return os.path.basename(name)[:-len(".whl")].split("-")[-1] == "any"


def pure_packages(wheels: list[str]) -> set[str]:
    """The packages the manifest bundles as a platform-independent wheel (exactly one file for
    all platforms and Pythons; more than one, or a platform wheel beside it, is an error)."""
    pure = {wheel_package(w) for w in wheels if is_pure(w)}
    for pkg in sorted(pure):
        named = [os.path.basename(w) for w in wheels if wheel_package(w) == pkg]
        if len(named) != 1:
            raise SystemExit(f"extension_tool: the manifest names {named} for {pkg}: a "
                             "platform-independent wheel serves every platform and Python "
                             "alone, so list exactly one")
    return pure


def wheel_platform(name: str) -> str | None:
    """The Blender platform a wheel file name is for (by its platform tag), or None (a
    platform-independent wheel too: :func:`is_pure`)."""
    tag = os.path.basename(name)[:-len(".whl")].split("-")[-1]
    if "manylinux" in tag and tag.endswith("x86_64"):
        return "linux-x64"
    if tag == "win_amd64":
        return "windows-x64"
    if tag.startswith("macosx_") and tag.endswith("_arm64"):
        return "macos-arm64"
    if tag.startswith("macosx_") and tag.endswith("_x86_64"):
        return "macos-x64"
    return None


#: Where the manifest's wheels are kept between checkouts (they are pinned by file name, so a
#: file there is the file the manifest names): a fresh clone copies them instead of downloading
#: them again (351 MB for the 25 wheels the manifest names with embreex and tzdata, tzdata's
#: 0.35 MB of it; ~240 MB before embreex).
WHEEL_CACHE = os.path.join(os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")),
                           "relightable-textures", "extension-wheels")


def _copy_atomically(src: str, dst: str) -> None:
    """``src`` copied to ``dst`` whole or not at all, through the project's one rename helper
    (lt_addon/io/atomic.py, loaded by path: this tool runs outside the package)."""
    spec = importlib.util.spec_from_file_location(
        "_relight_atomic", os.path.join(ROOT, "lt_addon", "io", "atomic.py"))
    atomic = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(atomic)
    with atomic.atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def ensure_wheels() -> list[str]:
    """The manifest's wheels in ./wheels: copied from :data:`WHEEL_CACHE`, else downloaded (and
    then kept there); returns their paths."""
    m = manifest()
    wanted = [os.path.normpath(os.path.join(ROOT, w)) for w in m.get("wheels", [])]
    unknown = [p for p in m.get("platforms", []) if p not in PIP_PLATFORMS]
    if unknown:
        raise SystemExit(f"extension_tool: no pip platform tags known for {unknown}")
    for w in wanted:
        cached = os.path.join(WHEEL_CACHE, os.path.basename(w))
        if not os.path.exists(w) and os.path.isfile(cached):
            os.makedirs(os.path.dirname(w), exist_ok=True)
            _copy_atomically(cached, w)
    pure = pure_packages(wanted)
    if any(not os.path.exists(w) for w in wanted):
        _require_pip("download the wheels of requirements-wheels.txt")
        dest = os.path.join(ROOT, "wheels")
        # what is there already is not asked for again: (package, platform, python tag)
        present = {(wheel_package(w), wheel_platform(w), os.path.basename(w).split("-")[-3])
                   for w in wanted if os.path.exists(w)}
        present_pure = {wheel_package(w) for w in wanted if is_pure(w) and os.path.exists(w)}
        # a platform-independent wheel (tzdata) once: the same file for every platform/Python
        for req in requirements():
            if wheel_package(req) in pure - present_pure:
                subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                                "--only-binary=:all:", "-d", dest, req], check=True)
        for platform in m.get("platforms", []):
            for python in PYTHONS:
                for req in requirements():
                    name = wheel_package(req)
                    if name in pure or \
                            (name, platform, "cp" + python.replace(".", "")) in present:
                        continue
                    tags = NEWER_PLATFORMS.get(name, {}).get(platform, PIP_PLATFORMS[platform])
                    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                           "--only-binary=:all:", "--python-version", python,
                           "--implementation", "cp", "-d", dest, req]
                    for tag in tags:
                        cmd += ["--platform", tag]
                    subprocess.run(cmd, check=True)
    still = [w for w in wanted if not os.path.exists(w)]
    if still:
        raise SystemExit("extension_tool: manifest wheels not downloaded (check the file names "
                         "in blender_manifest.toml against requirements-wheels.txt): "
                         + ", ".join(os.path.basename(w) for w in still))
    try:
        os.makedirs(WHEEL_CACHE, exist_ok=True)
        for w in wanted:
            cached = os.path.join(WHEEL_CACHE, os.path.basename(w))
            if not os.path.exists(cached):
                _copy_atomically(w, cached)
    except OSError as exc:   # a read-only or full cache only costs the next clone a download
        print(f"extension_tool: note: could not keep the wheels in {WHEEL_CACHE}: {exc}",
              file=sys.stderr)
    return wanted


def check_zip(zip_path: str, platform: str, wheels: list[str]) -> None:
    """The zip holds exactly the manifest's wheels for ``platform``: both Pythons of every
    platform-specific package of requirements-wheels.txt, the one wheel of each
    platform-independent package (tzdata), nothing of another platform."""
    inside = sorted(os.path.basename(n) for n in zipfile.ZipFile(zip_path).namelist()
                    if n.endswith(".whl"))
    expected = sorted(os.path.basename(w) for w in wheels
                      if wheel_platform(w) == platform or is_pure(w))
    pure = pure_packages(wheels)
    reqs = [wheel_package(r) for r in requirements()]
    count = sum(1 if r in pure else len(PYTHONS) for r in reqs)
    if inside != expected or len(expected) != count or \
            sorted({wheel_package(w) for w in expected}) != sorted(reqs):
        raise SystemExit(f"extension_tool: {os.path.basename(zip_path)} holds wheels {inside}, "
                         f"expected {expected}")


def build(output_dir: str, blender: str | None = None,
          wheelhouse: str = WHEELHOUSE) -> dict[str, str]:
    """Validate the source tree, build one zip per platform into ``output_dir``, validate and
    check each; returns {blender platform: zip path}. ``blender``: a Blender executable whose
    extension tool to use (else this Python's bpy, else the pinned bpy wheel's)."""
    wheels = ensure_wheels()
    os.makedirs(output_dir, exist_ok=True)
    m = manifest()
    base = os.path.join(os.path.abspath(output_dir), f"{m['id']}-{m['version']}.zip")
    with tempfile.TemporaryDirectory(prefix="relight-ext-tool-") as workdir:
        tool = extension_tool(blender, wheelhouse, workdir)
        print(f"extension_tool: Blender's extension tool from {tool.origin}", file=sys.stderr)
        tool.run("validate", ROOT)
        tool.run("build", "--source-dir", ROOT, "--split-platforms", "--output-filepath", base)
        zips = {}
        for platform in m["platforms"]:
            zip_path = base[:-len(".zip")] + "-" + platform.replace("-", "_") + ".zip"
            if not os.path.exists(zip_path):
                raise SystemExit(f"extension_tool: the extension tool did not write {zip_path}")
            tool.run("validate", zip_path)
            check_zip(zip_path, platform, wheels)
            zips[platform] = zip_path
    return zips


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", default=os.path.join(ROOT, "dist"))
    parser.add_argument("--blender", metavar="PATH",
                        help="a Blender 4.2+ executable (or macOS Blender.app) whose extension "
                             "tool to use; default: this Python's bpy, else the pinned bpy wheel")
    parser.add_argument("--wheelhouse", default=WHEELHOUSE,
                        help="where the pinned bpy wheel is looked for and downloaded "
                             "(default: %(default)s, make venv's)")
    args = parser.parse_args()
    for platform, path in build(args.output_dir, args.blender, args.wheelhouse).items():
        print(platform, path)


if __name__ == "__main__":
    main()
