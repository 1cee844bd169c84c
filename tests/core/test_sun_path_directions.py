"""Directions along an animated sun's path (lt_addon/sphere/sun_path.py)."""

import numpy as np
import pytest

from relightable_textures.lt_addon.sphere.sun_path import densify, upper_voronoi_areas, with_path
from relightable_textures.lt_addon.transport.bundle import split_sun_path
from relightable_textures.lt_addon.errors import InputError
from relightable_textures.lt_addon.transport.texture import parse_directions


def _day(n=25):
    az = np.radians(np.linspace(80, 280, n))
    el = np.radians(60 * np.sin(np.linspace(-0.05, np.pi + 0.05, n)))
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)


def test_densified_path_is_step_apart_on_the_curve_and_above_the_horizon():
    pts = densify(_day(), 0.5)
    gaps = np.degrees(np.arccos(np.clip(np.sum(pts[1:] * pts[:-1], 1), -1, 1)))
    assert gaps.max() <= 0.5 + 1e-9 and (pts[:, 2] > 0).all()
    assert np.allclose(np.linalg.norm(pts, axis=1), 1)
    # the arc length of the day above the horizon, walked in half degrees
    assert abs(len(pts) - gaps.sum() / 0.5) < 30


def test_with_path_keeps_the_base_and_adds_the_path_with_solid_angles():
    base = parse_directions("hemi:400:1.5")
    d = with_path(base, _day(), 0.5)
    p = d.params
    assert p["base_kept"] + p["base_dropped"] == 400 and p["sun_path_directions"] > 300
    assert d.size == p["base_kept"] + p["sun_path_directions"]
    assert d.solid_angles.sum() == pytest.approx(2 * np.pi)
    # cells along the path are small (dense), the base's large: a sun on the path has a
    # baked direction within a quarter step
    on = densify(_day(), 0.1)
    nearest = np.degrees(np.arccos(np.clip((on @ d.directions.T).max(1), -1, 1)))
    assert nearest.max() < 0.26
    base_cells = np.median(d.solid_angles[:p["base_kept"]])
    assert np.median(d.solid_angles[-p["sun_path_directions"]:]) < 0.1 * base_cells


def test_voronoi_areas_of_a_uniform_set_are_uniform():
    base = parse_directions("hemi:900")          # equal-area Fibonacci spiral
    a = upper_voronoi_areas(base.directions)
    assert a.sum() == pytest.approx(2 * np.pi)
    assert np.median(np.abs(a / (2 * np.pi / 900) - 1)) < 0.1


def test_the_spec_suffix():
    assert split_sun_path("hemi:1600:1.5") == ("hemi:1600:1.5", None)
    assert split_sun_path("hemi:1600:1.5+sun-path") == ("hemi:1600:1.5", 0.5)
    assert split_sun_path("hemi:400+sun-path:0.25") == ("hemi:400", 0.25)
    for bad in ("hemi:400+sun-path:x", "hemi:400+sun-path:20", "hemi:400+sun-pathX"):
        with pytest.raises(InputError):
            split_sun_path(bad)


def test_a_band_is_parallel_copies_step_apart():
    from relightable_textures.lt_addon.sphere.sun_path import band

    pts = densify(_day(), 0.5)
    b = band(pts, 0.5, 1.0)                           # offsets -0.5, 0, +0.5 degrees
    assert len(b) <= 3 * len(pts) and len(b) > 2.9 * len(pts)
    off = np.degrees(np.arccos(np.clip(b[len(pts):2 * len(pts)] @ pts.T, -1, 1)).min(axis=1))
    assert np.abs(off[10:-10] - 0.5).max() < 0.02     # half a degree off the curve
    assert len(band(pts, 0.5, 0.0)) == len(pts)
