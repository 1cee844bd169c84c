"""Charts of the development tools (matplotlib): the data land where they should."""

import numpy as np
import pytest

pytest.importorskip("matplotlib")   # in requirements.txt; absent only outside the dev venv

from matplotlib.image import imread  # noqa: E402

from relightable_textures.devtools import charts  # noqa: E402

RED, BLUE = (255, 0, 0), (0, 0, 255)


def _pixels_of(img, rgb, tol=0.08):
    """(rows, cols) of the pixels of colour ``rgb`` (0..255) in a 0..1 RGB(A) image."""
    target = np.array(rgb, float) / 255
    return np.nonzero(np.all(np.abs(img[..., :3] - target) < tol, axis=2))


def test_points_land_in_data_order_and_the_file_has_the_size_asked(tmp_path):
    path = tmp_path / "c.png"
    # no labels, so no legend whose markers would add pixels of the same colours
    n = charts.write_chart(str(path), [charts.Series([0, 1], [0, 0], color=RED, line=False),
                                       charts.Series([0, 1], [1, 1], color=BLUE, line=False)],
                           title="t", xlabel="x", ylabel="y", width=320, height=240)
    img = imread(str(path))
    assert img.shape[:2] == (240, 320) and n == path.stat().st_size
    red_rows, red_cols = _pixels_of(img, RED)
    blue_rows, _ = _pixels_of(img, BLUE)
    assert red_rows.size and blue_rows.size
    assert blue_rows.mean() < red_rows.mean()              # y = 1 is drawn above y = 0
    left = red_cols < red_cols.mean()                       # two markers, x = 0 and x = 1
    assert left.any() and (~left).any()
    assert abs(red_rows[left].mean() - red_rows[~left].mean()) < 2   # same y, same row
    assert [p.name for p in tmp_path.iterdir()] == ["c.png"]


def test_non_positive_values_are_dropped_on_log_axes(tmp_path):
    path = tmp_path / "log.png"
    charts.write_chart(str(path), [charts.Series([-1, 0, np.nan], [1, 2, 3], color=RED)],
                       logx=True)
    assert _pixels_of(imread(str(path)), RED)[0].size == 0   # nothing drawable, nothing drawn


def test_invalid_series_are_rejected():
    with pytest.raises(ValueError, match="differ in length"):
        charts.Series([1, 2], [1])
    with pytest.raises(ValueError, match="marker"):
        charts.Series([1], [1], marker="*")
    with pytest.raises(ValueError, match="highlight"):
        charts.Series([1, 2], [1, 2], highlight=[True])
    with pytest.raises(ValueError, match="color"):
        charts.Series([1], [1], color=(300, 0, 0))


def test_analysis_charts_of_a_report(tmp_path):
    report = {"object": "Statue", "N": 96, "tol": 1e-3, "optimum": {"clusters": 8},
              "predicted_clusters": 6,
              "dimensionality": {"slope": 0.7, "curves": [
                  {"seed": 0, "slope": 0.7, "sizes": [4, 16, 64], "dims": [3, 8, 21]}]},
              "cost_curve": [{"clusters": k, "cost_per_vertex": c}
                             for k, c in ((1, 90.0), (4, 40.0), (8, 30.0), (16, 35.0))],
              "adaptive": {"clusters": 8, "cost_per_vertex": 31.0},
              "auto": {"clusters": 6, "cost_per_vertex": 32.0}}
    paths = charts.analysis_charts(report, str(tmp_path), "Statue")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Statue_cost.png",
                                                          "Statue_dimensionality.png"]
    for p in paths.values():
        img = imread(p)[..., :3]
        assert img.shape == (420, 640, 3) and 0.02 < np.mean(img.min(axis=2) < 0.8) < 0.5
