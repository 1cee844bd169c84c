"""What a bake's report records as a caveat, as lines for the user (issue 59).

Every bake report (texture, lobes, vertex, material) keeps its figures in JSON; some of them
say the result is not what Cycles renders -- overlapping UV islands, a cross-check of the rays
against Cycles past its tolerance, a stage that fell back to Cycles, a target error not met.
:func:`report_warnings` turns a report into those lines, once each; the reports store them under
``"warnings"``, the CLI prints each as ``relight: warning: <line>`` on stderr and the panel
shows them as WARNING reports and in its last-bake box.
"""

from __future__ import annotations

#: Share of the covered texels with more than one UV triangle above which a bake warns (a seam,
#: a texel centre on an edge two triangles share, counts once: :func:`.geometry.uv_layout.
#: uv_coverage` nudges the centres off the edges).
UV_OVERLAP_WARNING = 0.01
#: The direct light by rays against Cycles' bake of the checked directions
#: (:func:`operators.base.direct_rays.direct_agreement`): a vertex where two edges meet exactly
#: may differ by Cycles' intersection tie-break -- measured at most 2 of 2,800 values (material
#: bake) and 2 of 688 (vertex bake, 0.3 %) on smooth meshes -- so a share of values more than
#: 1e-4 apart above 1 %, or a relative difference above 5 %, is a disagreement.
DIRECT_APART_WARNING = 0.01
DIRECT_REL_WARNING = 0.05


def uv_overlap(name: str, layout: dict | None) -> str | None:
    """The warning for ``layout`` (:func:`.geometry.uv_layout.uv_overlap_report`) of object
    ``name``, or None under :data:`UV_OVERLAP_WARNING`."""
    share = (layout or {}).get("overlapping", 0.0)
    if share <= UV_OVERLAP_WARNING:
        return None
    return (f"{name}: {100 * share:.1f}% of the covered texels have overlapping UVs (checked at "
            f"{layout.get('resolution', '?')}^2); those texels mix several faces, the last "
            "one baked wins (unwrap without overlaps)")


def direct_check(name: str, direct: dict | None) -> str | None:
    """The warning for a direct term by rays whose check against Cycles (``direct.vs_cycles``)
    is past its tolerance, or None."""
    check = (direct or {}).get("vs_cycles")
    if not check:
        return None
    apart, rel = check.get("values_apart", 0.0), check.get("rel_difference", 0.0)
    if apart <= DIRECT_APART_WARNING and rel <= DIRECT_REL_WARNING:
        return None
    n = direct.get("checked_directions", "some")
    return (f"{name}: the direct light by rays disagrees with Cycles' bake of {n} of its "
            f"directions: relative difference {rel:.2g}, {100 * apart:.2g}% of values more "
            f"than 1e-4 apart (tolerance {100 * DIRECT_APART_WARNING:g}% and "
            f"{DIRECT_REL_WARNING:g}); --direct cycles bakes it as Cycles renders it")


def report_warnings(report: dict) -> list:
    """Every caveat ``report`` records, as lines naming the object, in a fixed order, each
    once."""
    name = report.get("object") or ", ".join(report.get("objects", ())) or "the bake"
    out = [uv_overlap(name, report.get("uv_layout")), direct_check(name, report.get("direct"))]
    unused = (report.get("direct") or {}).get("workers_unused")
    out.append(unused)
    indirect = report.get("indirect") or {}
    if indirect.get("method") == "steerable" and indirect.get("why"):
        out.append(f"{name}: the indirect light fell back to Cycles' steerable bake: "
                   f"{indirect['why']}")
    te = report.get("target_error") or {}
    if te and "met" in te and not te["met"]:
        out.append(f"{name}: target error {te['target_error']} not met: achieved "
                   f"{te.get('achieved', float('nan')):.3f} with {te['chosen_directions']} "
                   "directions")
    out += list(report.get("notes") or ())                       # the material bake's
    out += list((report.get("preview") or {}).get("warnings") or ())   # the vertex preview's
    seen = []
    for line in out:
        if line and line not in seen:
            seen.append(line)
    return seen


def all_warnings(reports) -> list:
    """The warnings of several reports (objects baked together), each line once."""
    seen = []
    for rep in reports:
        for line in rep.get("warnings", report_warnings(rep)):
            if line not in seen:
                seen.append(line)
    return seen
