"""Pareto masks vs brute force, preset choice on hand-worked fronts, atomic CSV, error metrics."""

import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from relightable_textures.devtools.pareto import (
    choose_presets,
    error_metrics,
    pareto_mask,
    pareto_mask_nd,
    read_csv,
    write_csv,
)


def brute_force_mask(matrix):
    """Literal definition: i is optimal iff it has no NaN and no NaN-free j dominates it."""
    rows = [list(map(float, r)) for r in matrix]
    ok = [not any(math.isnan(v) for v in r) for r in rows]
    out = []
    for i, a in enumerate(rows):
        if not ok[i]:
            out.append(False)
            continue
        dominated = False
        for j, b in enumerate(rows):
            if j == i or not ok[j]:
                continue
            if all(y <= x for x, y in zip(a, b)) and any(y < x for x, y in zip(a, b)):
                dominated = True
                break
        out.append(not dominated)
    return np.array(out, dtype=bool)


# small integer grid values force many ties; NaN and inf are mixed in
values = st.one_of(
    st.integers(0, 5).map(float),
    st.floats(-10, 10, allow_nan=False),
    st.sampled_from([math.nan, math.inf]),
)


# --------------------------------------------------------------------------- masks


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(values, values), min_size=0, max_size=30))
def test_pareto_mask_equals_brute_force(pairs):
    c = np.array([p[0] for p in pairs], dtype=float)
    e = np.array([p[1] for p in pairs], dtype=float)
    got = pareto_mask(c, e)
    assert got.dtype == bool and got.shape == (len(pairs),)
    np.testing.assert_array_equal(got, brute_force_mask(pairs))


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 4).flatmap(
    lambda m: st.lists(st.lists(values, min_size=m, max_size=m), min_size=1, max_size=25)))
def test_pareto_mask_nd_equals_brute_force(rows):
    got = pareto_mask_nd(np.array(rows, dtype=float))
    np.testing.assert_array_equal(got, brute_force_mask(rows))


def test_hand_mask_ties_and_nan():
    c = [1, 2, 2, 3, 1, np.nan, 0.5, 5]
    e = [5, 3, 3, 1, 5, 0.0, np.nan, 1]
    # (1,5) twice and (2,3) twice: ties, all kept; (3,1) kept; (5,1) dominated by (3,1).
    # The NaN rows are never optimal and dominate nothing, although (NaN, 0) and (0.5, NaN)
    # would beat other points on their finite objective.
    np.testing.assert_array_equal(
        pareto_mask(c, e), [True, True, True, True, True, False, False, False])


def test_mask_shapes_validated():
    with pytest.raises(ValueError):
        pareto_mask([1, 2], [1, 2, 3])
    with pytest.raises(ValueError):
        pareto_mask([[1, 2]], [[1, 2]])
    with pytest.raises(ValueError):
        pareto_mask_nd([1, 2, 3])
    assert pareto_mask([], []).shape == (0,)


# --------------------------------------------------------------------------- presets


def pts(*ce, key_c="bake_seconds", key_e="rel_rmse"):
    return [{"name": f"p{i}", key_c: c, key_e: e} for i, (c, e) in enumerate(ce)]


def test_hand_front_draft_balanced_production():
    # front: (1, 1.0) (10, 0.1) (100, 0.05) (1000, 0.01); dominated: (50, 0.5), (2000, 0.02)
    # log10 cost -> x = 0, 1/3, 2/3, 1; log10 err = 0, -1, -1.301, -2 -> y = 1, .5, .349, 0
    # distances to (0,0): 1, 0.601, 0.752, 1 -> knee = (10, 0.1)
    points = pts((50, 0.5), (1000, 0.01), (1, 1.0), (2000, 0.02), (100, 0.05), (10, 0.1))
    got = choose_presets(points)
    assert list(got) == ["draft", "balanced", "production"]
    assert got["draft"]["name"] == "p2"
    assert got["balanced"]["name"] == "p5"
    assert got["production"]["name"] == "p1"
    # the chosen dicts are copies of the points plus "why"
    assert got["production"]["bake_seconds"] == 1000 and "why" not in points[1]
    assert got["production"]["why"].startswith(
        "lowest error on the Pareto front: rel_rmse 0.01 at 1000 s")
    assert got["draft"]["why"].startswith("cheapest point on the Pareto front: rel_rmse 1 at 1 s")
    assert "distance 0.601" in got["balanced"]["why"]
    assert "rel_rmse 0.1 at 10 s" in got["balanced"]["why"]
    assert "4 distinct point(s)" in got["balanced"]["why"]
    assert "2 dominated" in got["balanced"]["why"]


def test_knee_on_end_point_moves_toward_middle():
    # concave front: costs 1, 100, 101; errors 1, 0.99, 0.01. Normalised:
    # (0, 1), (0.998, 0.998), (1, 0) -> ends at distance 1, middle at 1.41; the knee tie goes to
    # the cheaper end (draft), which is then moved to the next front point toward the middle.
    got = choose_presets(pts((1, 1.0), (100, 0.99), (101, 0.01)))
    assert [got[n]["name"] for n in ("draft", "balanced", "production")] == ["p0", "p1", "p2"]
    assert "next front point toward the middle" in got["balanced"]["why"]
    assert "cheapest end point" in got["balanced"]["why"]
    for d in got.values():
        assert "shares" not in d["why"]


def test_knee_alone_as_custom_rule_on_concave_front():
    # costs 1, 90, 95, 100 -> x = 0, .977, .989, 1; errors 1, .99, .98, .01 -> y = 1, .998, .996, 0:
    # interior points are ~1.4 from utopia, both ends exactly 1 -> cheaper end, moved to index 1.
    got = choose_presets(pts((1, 1.0), (90, 0.99), (95, 0.98), (100, 0.01)),
                         rules={"mid": "knee"})
    assert list(got) == ["mid"] and got["mid"]["name"] == "p1"
    assert "next front point toward the middle" in got["mid"]["why"]


def test_custom_rules_and_callable():
    points = pts((1, 1.0), (10, 0.1), (100, 0.05), (1000, 0.01), (50, 0.5))

    def second_cheapest(costs, errors):
        assert np.all(np.diff(costs) > 0) and np.all(np.diff(errors) < 0)
        return 1

    got = choose_presets(points, rules={"best": "lowest_error", "fast": "cheapest",
                                        "x": second_cheapest})
    assert list(got) == ["best", "fast", "x"]
    assert got["best"]["name"] == "p3" and got["fast"]["name"] == "p0"
    assert got["x"]["name"] == "p1" and "second_cheapest" in got["x"]["why"]
    with pytest.raises(ValueError, match="index"):
        choose_presets(points, rules={"bad": lambda c, e: 4})  # front has 4 points: 0..3
    with pytest.raises(ValueError):
        choose_presets(points, rules={"bad": "fastest"})
    with pytest.raises(ValueError):
        choose_presets(points, names=("a", "b"))


def test_other_keys():
    points = [
        {"id": "a", "stored_bytes": 4096, "psnr_db": 30, "max_abs_error": 0.2},
        {"id": "b", "stored_bytes": 1024, "psnr_db": 25, "max_abs_error": 0.4},
        {"id": "c", "stored_bytes": 8192, "psnr_db": 40, "max_abs_error": 0.3},  # dominated by a
    ]
    got = choose_presets(points, cost_key="stored_bytes", error_key="max_abs_error")
    assert got["draft"]["id"] == "b" and got["production"]["id"] == "a"
    assert "4096 bytes" in got["production"]["why"]


def test_ties_first_seen_point_represents_duplicates():
    points = pts((10, 0.5), (10, 0.5), (1, 2.0), (100, 0.1), (100, 0.1))
    got = choose_presets(points)
    assert got["draft"]["name"] == "p2"
    assert got["balanced"]["name"] == "p0"
    assert got["production"]["name"] == "p3"


def test_nan_none_and_inf_points_are_excluded():
    points = pts((1, math.nan), (0.1, None), (math.inf, 0.0), (5, 0.5), (50, 0.05), (500, 0.01),
                 (math.nan, 0.001))
    got = choose_presets(points)
    assert got["draft"]["name"] == "p3"
    assert got["production"]["name"] == "p5"
    assert got["balanced"]["name"] == "p4"
    assert "4 non-finite" in got["draft"]["why"]


@pytest.mark.parametrize("ce, front_size", [
    ([(3, 0.2)], 1),
    ([(3, 0.2), (3, 0.2), (4, 0.3)], 1),
    ([(3, 0.2), (30, 0.02), (40, 0.3)], 2),
])
def test_fewer_than_three_front_points_share(ce, front_size):
    got = choose_presets(pts(*ce))
    names = {n: d["name"] for n, d in got.items()}
    if front_size == 1:
        assert set(names.values()) == {"p0"}
        for d in got.values():
            assert "shares this point" in d["why"] and "only 1 distinct" in d["why"]
    else:
        # two end points at distance 1 each: the knee tie goes to the cheaper point
        assert names == {"draft": "p0", "balanced": "p0", "production": "p1"}
        assert "shares this point with balanced" in got["draft"]["why"]
        assert "shares this point with draft" in got["balanced"]["why"]
        assert "only 2 distinct" in got["balanced"]["why"]
        assert "shares" not in got["production"]["why"]


def test_zero_error_uses_linear_error_axis():
    # error 0 cannot be logged: that axis is scaled linearly; production is the zero-error point.
    # x (log cost) = 0, 0.5, 1; y (linear err) = 1, 0.1, 0 -> knee = middle.
    got = choose_presets(pts((1, 1.0), (10, 0.1), (100, 0.0)))
    assert got["production"]["name"] == "p2" and got["balanced"]["name"] == "p1"
    assert "linear rel_rmse" in got["balanced"]["why"]
    assert "log bake_seconds" in got["balanced"]["why"]


def test_errors_on_bad_input():
    with pytest.raises(ValueError, match="no points"):
        choose_presets([])
    with pytest.raises(ValueError, match="rel_rmse"):
        choose_presets([{"bake_seconds": 1}])
    with pytest.raises(ValueError, match="missing"):
        choose_presets([{"bake_seconds": 1, "rel_rmse": 0.1}, {"rel_rmse": 0.2}])
    with pytest.raises(ValueError, match="finite"):
        choose_presets(pts((math.nan, 1.0), (1.0, math.inf), (None, None)))
    with pytest.raises(ValueError, match="numeric"):
        choose_presets(pts(("fast", 1.0)))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(values, values), min_size=1, max_size=25))
def test_presets_never_dominated(pairs):
    finite = [(c, e) for c, e in pairs if math.isfinite(c) and math.isfinite(e)]
    points = pts(*pairs)
    if not finite:
        with pytest.raises(ValueError):
            choose_presets(points)
        return
    got = choose_presets(points)
    for d in got.values():
        c, e = d["bake_seconds"], d["rel_rmse"]
        assert math.isfinite(c) and math.isfinite(e)
        assert not any(c2 <= c and e2 <= e and (c2 < c or e2 < e) for c2, e2 in finite)
    min_c = min(c for c, _ in finite)
    assert got["draft"]["bake_seconds"] == min_c
    assert got["draft"]["rel_rmse"] == min(e for c, e in finite if c == min_c)
    assert got["production"]["rel_rmse"] == min(e for _, e in finite)
    n_front = len({(c, e) for c, e in finite
                   if not any(c2 <= c and e2 <= e and (c2 < c or e2 < e) for c2, e2 in finite)})
    chosen = {(d["bake_seconds"], d["rel_rmse"]) for d in got.values()}
    assert len(chosen) == min(3, n_front)


# --------------------------------------------------------------------------- CSV


def test_csv_round_trip_nested_and_atomic(tmp_path):
    rows = [
        {"order": 3, "rel_rmse": 0.1 + 0.2, "settings": {"samples": 64, "half": True}},
        {"order": 5, "psnr_db": np.float64(1 / 3), "dirs": [1, 2.5, "x"], "note": 'a,"b"\nc'},
        {"rel_rmse": np.float32(0.1), "missing": None, "arr": np.arange(3), "flag": False},
    ]
    path = tmp_path / "sweep.csv"
    n = write_csv(path, rows)
    assert n == path.stat().st_size > 0
    assert os.listdir(tmp_path) == ["sweep.csv"]  # no temporary file left

    back = read_csv(path)
    assert list(back[0]) == ["order", "rel_rmse", "settings", "psnr_db", "dirs", "note",
                             "missing", "arr", "flag"]
    assert back[0]["rel_rmse"] == "0.30000000000000004"
    assert float(back[0]["rel_rmse"]) == 0.1 + 0.2
    assert float(back[1]["psnr_db"]) == 1 / 3
    assert float(back[2]["rel_rmse"]) == float(np.float32(0.1))
    assert back[0]["psnr_db"] == "" and back[2]["missing"] == ""
    import json
    assert json.loads(back[0]["settings"]) == {"samples": 64, "half": True}
    assert json.loads(back[1]["dirs"]) == [1, 2.5, "x"]
    assert json.loads(back[2]["arr"]) == [0, 1, 2]
    assert back[1]["note"] == 'a,"b"\nc'
    assert back[0]["order"] == "3" and back[2]["flag"] == "False"

    # overwrite: replaced atomically, still one file
    n2 = write_csv(path, [{"a": 1}])
    assert n2 == path.stat().st_size == len(b"a\n1\n")
    assert read_csv(path) == [{"a": "1"}]
    assert os.listdir(tmp_path) == ["sweep.csv"]


def test_csv_failure_leaves_old_file_and_no_temp(tmp_path):
    path = tmp_path / "sweep.csv"
    write_csv(path, [{"a": 1}])
    with pytest.raises(TypeError):
        write_csv(path, [{"a": [object()]}])
    assert read_csv(path) == [{"a": "1"}]
    assert os.listdir(tmp_path) == ["sweep.csv"]
    # no rows -> empty file
    assert write_csv(tmp_path / "empty.csv", []) == 0
    assert read_csv(tmp_path / "empty.csv") == []
    assert sorted(os.listdir(tmp_path)) == ["empty.csv", "sweep.csv"]


# --------------------------------------------------------------------------- error metrics


def test_error_metrics_hand_values():
    ref = np.array([1.0, 2.0, 3.0, 4.0])
    est = ref + np.array([1.0, -1.0, 0.0, 0.0])
    m = error_metrics(est, ref)
    # mse = 2/4 = 0.5, peak = 4 -> PSNR = 10 log10(16 / 0.5) = 10 log10 32
    assert m["mse"] == 0.5
    assert m["rmse"] == pytest.approx(math.sqrt(0.5))
    assert m["peak"] == 4.0
    assert m["psnr_db"] == pytest.approx(10 * math.log10(32)) and m["psnr_db"] == pytest.approx(
        15.051499783199059)
    assert m["rel_rmse"] == pytest.approx(math.sqrt(2) / math.sqrt(30))
    assert m["max_abs_error"] == 1.0
    assert all(type(v) is float for v in m.values())
    # explicit peak 1: PSNR = 10 log10(1 / 0.5) = 3.0103 dB
    assert error_metrics(est, ref, peak=1.0)["psnr_db"] == pytest.approx(10 * math.log10(2))


def test_error_metrics_any_shape_and_int_input():
    ref = np.arange(24, dtype=np.int32).reshape(2, 3, 4)
    est = ref.astype(np.float32) + 0.5
    m = error_metrics(est, ref)
    assert m["max_abs_error"] == 0.5 and m["mse"] == 0.25
    assert m["rel_rmse"] == pytest.approx(0.5 * math.sqrt(24) / math.sqrt(np.sum(ref.astype(float) ** 2)))
    assert m["psnr_db"] == pytest.approx(10 * math.log10(23.0 ** 2 / 0.25))


def test_error_metrics_edge_cases():
    z = np.zeros((4, 4, 3))
    m = error_metrics(z, z)
    assert m["rel_rmse"] == 0.0 and m["psnr_db"] == math.inf and m["max_abs_error"] == 0.0
    x = np.full((4, 4, 3), 0.25)
    m = error_metrics(x, z)
    assert m["rel_rmse"] == math.inf and m["psnr_db"] == -math.inf and m["max_abs_error"] == 0.25
    m = error_metrics(x, x.copy())
    assert m["rel_rmse"] == 0.0 and m["psnr_db"] == math.inf and m["max_abs_error"] == 0.0
    with pytest.raises(ValueError, match="shape"):
        error_metrics(np.zeros(3), np.zeros((3, 1)))
    with pytest.raises(ValueError):
        error_metrics([], [])
