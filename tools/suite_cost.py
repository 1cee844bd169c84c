"""Where the test suite's time goes, from pytest's JUnit XML (``make test`` writes
``build/test-report.xml``): the cost of each test file and the slowest tests, as Markdown.

A test's seconds are pytest's ``time`` attribute: setup + call + teardown, so a module fixture
that bakes once is charged to the first test that uses it. Seconds are wall-clock on the
machine that ran the suite (2 cores in CI); compare files within one run, not across runs.

Usage: ``python3 tools/suite_cost.py build/test-report.xml [--slowest 30] [--before OLD.xml]``
(``--before`` adds the same file's seconds from an earlier report, for a before/after table).
"""

from __future__ import annotations

import argparse
import collections
import sys
import xml.etree.ElementTree as ET


def read_report(path: str) -> dict[str, float]:
    """{test id: seconds} of every test case in a JUnit XML report (skips count, 0 s or not)."""
    cases = {}
    for case in ET.parse(path).getroot().iter("testcase"):
        module = case.get("classname", "")
        # classname is dotted (tests.blender.test_x or tests.blender.test_x.TestClass)
        cases[f"{module}::{case.get('name')}"] = float(case.get("time", 0.0))
    return cases


def module_of(test_id: str) -> str:
    """``tests/blender/test_x.py`` from ``tests.blender.test_x[.Class]::name``."""
    parts = test_id.split("::", 1)[0].split(".")
    while parts and not parts[-1].startswith("test_"):
        parts.pop()   # a class name after the module
    return "/".join(parts) + ".py" if parts else test_id


def by_file(cases: dict[str, float]) -> dict[str, tuple[int, float]]:
    files: dict[str, list] = collections.defaultdict(lambda: [0, 0.0])
    for test_id, seconds in cases.items():
        row = files[module_of(test_id)]
        row[0] += 1
        row[1] += seconds
    return {f: (n, s) for f, (n, s) in files.items()}


def file_table(cases: dict[str, float], before: dict[str, float] | None = None) -> str:
    files = by_file(cases)
    old = by_file(before) if before else {}
    total = sum(s for _, s in files.values())
    head = "| file | tests | seconds | share |"
    rule = "|---|---:|---:|---:|"
    if before:
        head, rule = head + " seconds before |", rule + "---:|"
    rows = [head, rule]
    for f, (n, s) in sorted(files.items(), key=lambda kv: -kv[1][1]):
        row = f"| `{f}` | {n} | {s:.1f} | {100 * s / total:.1f} % |"
        if before:
            row += f" {old[f][1]:.1f} |" if f in old else " - |"
        rows.append(row)
    row = f"| **all** | {len(cases)} | {total:.1f} | 100 % |"
    if before:
        row += f" {sum(s for _, s in old.values()):.1f} |"
    rows.append(row)
    return "\n".join(rows)


def slowest_table(cases: dict[str, float], count: int) -> str:
    rows = ["| # | test | seconds |", "|---:|---|---:|"]
    ranked = sorted(cases.items(), key=lambda kv: -kv[1])[:count]
    for i, (test_id, seconds) in enumerate(ranked, 1):
        rows.append(f"| {i} | `{module_of(test_id)}::{test_id.split('::', 1)[1]}` | "
                    f"{seconds:.1f} |")
    return "\n".join(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", help="pytest --junitxml file")
    parser.add_argument("--slowest", type=int, default=30, help="how many slowest tests to list")
    parser.add_argument("--before", help="an earlier report, for a seconds-before column")
    args = parser.parse_args(argv)
    try:
        cases = read_report(args.report)
        before = read_report(args.before) if args.before else None
    except (OSError, ET.ParseError) as exc:
        print(f"suite_cost: error: cannot read the report: {exc}", file=sys.stderr)
        return 2
    if not cases:
        print(f"suite_cost: error: {args.report} holds no test case", file=sys.stderr)
        return 2
    print(f"### Cost by file ({len(cases)} tests, {sum(cases.values()):.0f} s)\n")
    print(file_table(cases, before))
    if args.slowest > 0:
        print(f"\n### The {args.slowest} slowest tests\n")
        print(slowest_table(cases, args.slowest))
    return 0


if __name__ == "__main__":
    sys.exit(main())
