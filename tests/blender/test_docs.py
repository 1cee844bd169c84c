"""The documentation: the generated CLI reference is current, every relative link and image in
README.md, docs/*.md and docs/bench/*.md resolves (files and ``#anchor`` headings), and the
README stays short.

The CLI reference is generated from ``build_parser()`` (tools/cli_reference.py), which imports
bpy: hence tests/blender. Everything else here reads Markdown files only.
"""

from __future__ import annotations

import importlib.util
import pathlib
import re
import unicodedata

import pytest

pytestmark = pytest.mark.blender

ROOT = pathlib.Path(__file__).resolve().parents[2]
README_MAX_LINES = 250

_FENCE = re.compile(r"^\s*(```|~~~)")
_HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
_CODE_SPAN = re.compile(r"`+[^`]*?`+", re.S)
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def _load_cli_reference():
    spec = importlib.util.spec_from_file_location("cli_reference",
                                                  ROOT / "tools" / "cli_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _prose(text: str) -> str:
    """The text outside fenced code blocks (fences blanked, so line numbers stay)."""
    out, fenced = [], False
    for line in text.split("\n"):
        if _FENCE.match(line):
            fenced = not fenced
            out.append("")
            continue
        out.append("" if fenced else line)
    return "\n".join(out)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: its text (inline code, emphasis and link targets
    dropped), lowercased, every character but letters, marks, digits, '-', '_' and spaces
    removed, each space a '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)   # [text](url) -> text
    text = text.lower()
    keep = []
    for ch in text:
        cat = unicodedata.category(ch)
        if ch in "-_" or cat[0] in "LMN":
            keep.append(ch)
        elif ch == " ":
            keep.append("-")
    return "".join(keep)


def anchors(path: pathlib.Path) -> set[str]:
    """Every heading anchor of a Markdown file, with GitHub's -1, -2 … for repeated ones."""
    seen: dict[str, int] = {}
    out = set()
    for line in _prose(path.read_text(encoding="utf-8")).split("\n"):
        m = _HEADING.match(line)
        if not m:
            continue
        base = slug(m.group(2))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def broken_links(files) -> list[str]:
    """``file:line: target: why`` for every relative link or image that does not resolve:
    a missing file, or an ``#anchor`` that is no heading of the target Markdown file."""
    problems = []
    cache: dict[pathlib.Path, set[str]] = {}
    for path in files:
        text = _prose(path.read_text(encoding="utf-8"))
        text = _CODE_SPAN.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)
        for m in _LINK.finditer(text):
            target = m.group(1)
            line = text.count("\n", 0, m.start()) + 1
            where = f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}:{line}"
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):   # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            dest = (path.parent / file_part).resolve() if file_part else path
            if not dest.exists():
                problems.append(f"{where}: {target}: no such file")
                continue
            if anchor and dest.suffix == ".md":
                if dest not in cache:
                    cache[dest] = anchors(dest)
                if anchor not in cache[dest]:
                    problems.append(f"{where}: {target}: no heading #{anchor} in {dest.name}")
    return problems


def _doc_files():
    """README, the docs and the dated measurement records under docs/bench."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
            *sorted((ROOT / "docs" / "bench").glob("*.md"))]


def test_cli_reference_is_generated_from_the_parser():
    expected = _load_cli_reference().reference()
    current = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    assert current == expected, (
        "docs/cli.md is out of date with the CLI's parser; regenerate it: "
        "python tools/cli_reference.py > docs/cli.md")


def test_every_relative_link_and_image_resolves():
    files = _doc_files()
    assert len(files) > 5
    problems = broken_links(files)
    assert not problems, "broken links:\n" + "\n".join(problems)


def test_readme_is_short():
    n = len((ROOT / "README.md").read_text(encoding="utf-8").splitlines())
    assert n <= README_MAX_LINES, (
        f"README.md has {n} lines (at most {README_MAX_LINES}): move detail into docs/")


def test_the_link_checker_sees_broken_links(tmp_path):
    (tmp_path / "b.md").write_text("# Some Title: `--flag` (2002)\n\n## Same\n\n## Same\n")
    (tmp_path / "pic.png").write_bytes(b"")
    a = tmp_path / "a.md"
    a.write_text("# A\n[ok](b.md#some-title---flag-2002) [ok](b.md#same-1) ![ok](pic.png)\n"
                 "[ok](#a) [web](https://example.com/x#y) `[not a link](nowhere.md)`\n"
                 "```\n[not a link](nowhere.md)\n```\n"
                 "[bad](c.md) [bad](b.md#nope) ![bad](gone.png)\n[bad](#b)\n")
    problems = broken_links([a])
    assert [p.split(": ")[1] for p in problems] == ["c.md", "b.md#nope", "gone.png", "#b"]
