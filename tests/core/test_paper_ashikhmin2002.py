"""The paper's numbers, through the report the CLI prints (relight validate --paper ashikhmin2002)."""

import json

import numpy as np
import pytest

from relightable_textures.lt_addon.checks import ashikhmin2002 as paper_checks


@pytest.fixture(scope="module")
def report():
    return paper_checks.ashikhmin2002_report()


def test_report_is_json_and_all_ok(report):
    again = json.loads(json.dumps(report))
    assert again == report
    for name, entry in report.items():
        assert set(entry) == {"value", "paper", "tolerance", "ok", "note"}, name
        assert entry["ok"], (name, entry)
    assert paper_checks.all_ok(report)


def test_reproduced_figures(report):
    assert abs(report["w"]["value"] - 1.492) <= 0.02
    assert -0.25 <= report["negative_lobe_ratio"]["value"] <= -0.15
    assert report["fit_kernel_error_ratio"]["value"] <= 1.02
    n = report["n100_vs_n200"]["value"]
    assert n["abs_dw"] <= 0.01 and n["max_light_diff_over_peak"] <= 0.015
    assert report["cond_default_centres"]["value"] < 2.0
    assert set(report["cond_by_order"]["value"]) == {str(k) for k in range(2, 13)}
    assert report["ring_set_singular"]["value"]["cond_aligned"] > 1e12
    peak = np.asarray(report["peak_location_0.3"]["value"])
    assert np.all(np.abs(peak - 0.3) <= 2 / 99)
    a = np.asarray(report["a_i"]["value"])
    assert a.shape == (7,) and np.all(np.diff(a) < 0)


def test_all_ok_detects_failure(report):
    bad = json.loads(json.dumps(report))
    bad["w"]["ok"] = False
    assert not paper_checks.all_ok(bad)
