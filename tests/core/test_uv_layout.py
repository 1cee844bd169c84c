"""UV coverage and overlap counts against hand-computed layouts."""

import numpy as np
import pytest

from relightable_textures.lt_addon.geometry.uv_layout import uv_coverage, uv_overlap_report


def grid_triangles(n):
    """The unit square split into n x n quads, each into two triangles along its diagonal."""
    t = np.linspace(0.0, 1.0, n + 1)
    tris = []
    for i in range(n):
        for j in range(n):
            a, b = (t[j], t[i]), (t[j + 1], t[i])
            c, d = (t[j + 1], t[i + 1]), (t[j], t[i + 1])
            tris += [(a, b, c), (a, c, d)]
    return np.array(tris)


def test_a_tiling_covers_every_texel_exactly_once_even_on_diagonals():
    for n, r in ((4, 16), (8, 8), (3, 17)):  # r = 2n: centres fall on the quad diagonals
        counts = uv_coverage(grid_triangles(n), r)
        assert counts.min() == 1 and counts.max() == 1
    assert uv_overlap_report(grid_triangles(4), 16) == {"resolution": 16, "covered": 1.0,
                                                        "overlapping": 0.0}


def test_mirrored_duplicate_island_is_all_overlap_and_half_coverage():
    left = grid_triangles(2) * [0.5, 1.0]  # the left half of the square
    twice = np.concatenate([left, left[:, ::-1]])  # same island again, opposite winding
    rep = uv_overlap_report(twice, 32)
    assert rep["covered"] == pytest.approx(0.5)
    assert rep["overlapping"] == pytest.approx(1.0)


def test_degenerate_and_outside_triangles_cover_nothing_and_bad_input_is_refused():
    tris = np.array([[[0.2, 0.2], [0.2, 0.2], [0.8, 0.8]],          # zero area
                     [[1.5, 1.5], [2.0, 1.5], [2.0, 2.0]]])          # outside [0, 1]^2
    assert uv_coverage(tris, 8).sum() == 0
    with pytest.raises(ValueError, match="shape"):
        uv_coverage(np.zeros((3, 2)), 8)
    with pytest.raises(ValueError, match="NaN"):
        uv_coverage(np.full((1, 3, 2), np.nan), 8)
