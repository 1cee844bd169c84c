"""The footprint's sub-sample pattern (lt_addon/rays/footprint.py): the jitter box of each
Blender release and each texel's shift of the lattice."""

import numpy as np
import pytest

from relightable_textures.lt_addon.rays import footprint as F


@pytest.mark.parametrize("version, box", [((4, 2, 13), 0.5), ((5, 0, 1), 0.5), ((5, 1, 2), 0.5),
                                          ((5, 2, 0), 0.5), ((5, 2, 1), 1.0), ((5, 3, 0), 1.0),
                                          ((6, 0, 0), 1.0)])
def test_the_jitter_box_follows_the_release_measured(version, box):
    # measured on each of these releases but 6.0 (tests/blender/test_footprint.py checks the
    # running Blender's own)
    assert F.jitter_box(version) == box


@pytest.mark.parametrize("box", [0.5, 1.0])
def test_shifted_lattices_stay_in_the_box_and_keep_one_sample_per_row_and_column(box):
    texel = np.arange(0, 4096 * 4096, 9973)
    shift = F.texel_shift(texel)
    assert shift.shape == (len(texel), 2) and (shift >= 0).all() and (shift < 1).all()
    assert np.array_equal(shift, F.texel_shift(texel.copy()))          # fixed per texel
    off = F.offsets(box=box, shift=shift)                                  # (M, 16, 2)
    assert off.shape == (len(texel), F.SAMPLES, 2)
    assert (np.abs(off) <= box / 2).all()
    # a shifted rank-1 lattice is still one sample in each of the 16 columns and rows
    for axis in (0, 1):
        cells = np.floor((off[..., axis] / box + 0.5) * F.SAMPLES).astype(int)
        assert all(len(np.unique(c)) == F.SAMPLES for c in cells[:50])
    # the shifts are spread: their mean over many texels is the box's centre, within the
    # standard error of a uniform variable (1/sqrt(12 M))
    se = 1 / np.sqrt(12 * len(texel))
    assert np.abs(shift.mean(axis=0) - 0.5).max() < 4 * se
    # unshifted: the one lattice of every texel
    assert np.allclose(F.offsets(box=box), F.offsets(box=box, shift=np.full((1, 2), 0.5 / 16))[0])


def test_thin_area_share_counts_the_uv_area_in_triangles_narrower_than_a_texel():
    # right isosceles triangles: legs a, inradius a (2 - sqrt 2) / 2, area a^2 / 2. Two of
    # legs 1/8 (inradius 0.0366 of the UV square) and one of legs 1/2 (0.146): the small ones
    # hold 1/9 of the area
    def tri(a):
        return [[0, 0], [a, 0], [0, a]]
    uv = np.array([tri(1 / 8), tri(1 / 8), tri(1 / 2)], float)
    assert F.thin_area_share(uv, 4) == 1.0                       # 0.59 texel: all thin
    assert F.thin_area_share(uv, 16) == pytest.approx(1 / 9)     # 0.59 and 2.3 texels
    assert F.thin_area_share(uv, 20) == pytest.approx(1 / 9)     # 0.73 and 2.9
    assert F.thin_area_share(uv, 40) == 0.0                      # 1.46 texels: none
    assert F.thin_area_share(np.zeros((0, 3, 2)), 64) == 0.0
