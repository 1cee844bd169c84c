"""What a report records as a caveat becomes one line each (issue 59): a per-vertex bake of a
cube said "relative difference 0.35, 19 % of values more than 1e-4 apart" only in its JSON and
a list of warnings left empty."""

from relightable_textures.lt_addon.caveats import all_warnings, report_warnings

CUBE = {"object": "Cube", "direct": {"engine": "rays", "checked_directions": 8,
                                     "vs_cycles": {"rel_difference": 0.35, "values_apart": 0.19}}}


def test_a_direct_check_past_its_tolerance_is_a_warning_naming_the_object():
    (line,) = report_warnings(CUBE)
    assert line.startswith("Cube: the direct light by rays disagrees with Cycles' bake of 8")
    assert "relative difference 0.35, 19% of values" in line


def test_within_tolerance_nothing_is_said():
    # the statue's measured worst: 2 of 688 values apart (a tie-break where edges meet)
    ok = {"object": "Statue", "direct": {"vs_cycles": {"rel_difference": 0.004,
                                                       "values_apart": 2 / 688}},
          "uv_layout": {"resolution": 256, "covered": 0.6, "overlapping": 0.009},
          "indirect": {"method": "none", "why": "the scene has no bounces"}}
    assert report_warnings(ok) == []


def test_overlaps_fallbacks_and_a_missed_target_each_once():
    rep = {"object": "Lap", "uv_layout": {"resolution": 16, "overlapping": 1.0},
           "indirect": {"method": "steerable", "why": "the ground reflects 40 %"},
           "target_error": {"target_error": 0.05, "met": False, "achieved": 0.08,
                            "chosen_directions": 1600}}
    lines = report_warnings(rep)
    assert len(lines) == 3
    assert lines[0].startswith("Lap: 100.0% of the covered texels have overlapping UVs")
    assert "fell back to Cycles' steerable bake: the ground reflects 40 %" in lines[1]
    assert "target error 0.05 not met: achieved 0.080" in lines[2]
    # objects baked together share a fallback line only when it names the same object
    both = all_warnings([{**rep, "warnings": lines}, {"object": "B", "warnings": [lines[1]]}])
    assert both == lines


def test_material_notes_and_idle_workers_are_said_as_they_are():
    rep = {"objects": ["Floor", "Wall"], "notes": ["4 one-bounce directions: coarse"],
           "direct": {"workers_unused": "the Dask workers were not used: ..."}}
    assert report_warnings(rep) == ["the Dask workers were not used: ...",
                                    "4 one-bounce directions: coarse"]
