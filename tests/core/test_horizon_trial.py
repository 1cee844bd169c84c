"""The trial of the horizon map on sampled tiles (lt_addon/transport/horizon_trial.py): at the
texels it scores, the map found on the sampled tiles alone relights exactly as the whole map
(so the sample's errors are the whole check's errors at those texels), against a whole map
found by the same rays; the tiles' spread; the decision rule."""

import numpy as np
import pytest

from relightable_textures.lt_addon.rays import engine, horizon
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el
from relightable_textures.lt_addon.transport import horizon_map as hmap
from relightable_textures.lt_addon.transport import horizon_trial as ht
from floor_points import floor_points

needs_engine = pytest.mark.skipif(not engine.available()[0], reason="embreex not installed")


def _grid(side, covered=None):
    """Flat indices of the covered texels of a ``side`` grid over the 4 m floor and their
    points' positions (texel centres; row along y, column along x)."""
    idx = np.arange(side * side) if covered is None else np.flatnonzero(covered)
    r, c = idx // side, idx % side
    P = np.column_stack([-2 + (c + 0.5) * 4 / side, -2 + (r + 0.5) * 4 / side, np.zeros(len(idx))])
    return idx, P


def _scene():
    """A 4 m floor with two walls and a post standing on it (casters, (V, T))."""
    quads = [[[0.5, -1.5, 0], [0.5, 0.2, 0], [0.5, 0.2, 0.8], [0.5, -1.5, 0.8]],
             [[-1.2, 1.0, 0], [0.3, 1.0, 0], [0.3, 1.0, 0.4], [-1.2, 1.0, 0.4]],
             [[-0.6, -0.6, 0], [-0.5, -0.6, 0], [-0.5, -0.6, 1.5], [-0.6, -0.6, 1.5]]]
    floor = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    V = np.concatenate([floor, np.concatenate(quads)])
    q = np.arange(1, len(V) // 4)[:, None] * 4
    T = np.concatenate([[[0, 1, 2], [0, 2, 3]], q + [0, 1, 2], q + [0, 2, 3]])
    return V, T


@needs_engine
@pytest.mark.parametrize("Rh, R", [(64, 64), (64, 128)])
def test_the_sampled_map_relights_the_scored_texels_as_the_whole_map(Rh, R):
    """Horizons found for the sampled tiles' points alone equal the whole run's there, bit for
    bit, and the map made of them relights every scored texel exactly as the whole map does
    (suns at 4-60 degrees, a 2-degree disc); scored texels lie in the sampled tiles and cover
    most of them. A part of the floor is left uncovered (a UV island's edge)."""
    V, T = _scene()
    occ = engine.Occluder(V, T)
    cov_h = np.ones((Rh, Rh), bool)
    cov_h[:, -Rh // 5:] = False
    cov = np.repeat(np.repeat(cov_h, R // Rh, 0), R // Rh, 1)
    h_tex, h_P = _grid(Rh, cov_h)
    tex, P = _grid(R, cov)
    h_pts, pts = floor_points(V, T, h_P), floor_points(V, T, P)
    A = 16
    whole = horizon.horizons(occ, h_pts, A)
    h_rows, t_rows = ht.pick(h_tex, Rh, tex, R, seed=3)
    assert 0 < len(h_rows) < len(h_tex) / 2 and len(t_rows) > 0.4 * len(h_rows) * (R // Rh) ** 2
    part = horizon.horizons(occ, h_pts.subset(h_rows), A)
    assert np.array_equal(part, whole[:, :, h_rows])
    H = np.zeros_like(whole)
    H[:, :, h_rows] = part
    coarse = (h_tex, Rh, None) if Rh < R else None
    full_map = hmap.from_points(whole, tex, R, pts.Ns, None, coarse=coarse)
    sample_map = hmap.from_points(H, tex, R, pts.Ns, None, coarse=coarse)
    lit_and_shadowed = 0
    for az, el in ((20, 4), (150, 9), (250, 25), (300, 60)):
        d = direction_from_az_el(az, el)
        a = full_map.direct(d, 2.0).reshape(-1)[tex[t_rows]]
        b = sample_map.direct(d, 2.0).reshape(-1)[tex[t_rows]]
        assert np.array_equal(a, b), (az, el)
        lit_and_shadowed += int(np.any(a == 0) and np.any(a > 0))
        # elsewhere the sampled map differs (it is open there): the texels are not all alike
        other = np.setdiff1d(np.arange(len(tex)), t_rows)
        assert np.any(full_map.direct(d, 2.0).reshape(-1)[tex[other]]
                      != sample_map.direct(d, 2.0).reshape(-1)[tex[other]]) or el > 30
    assert lit_and_shadowed >= 2        # the scored texels see shadows, not only open sky


def test_the_tiles_spread_over_the_texture_and_a_small_one_gets_no_trial():
    """One sampled tile per run of 8 covered tiles (stratified), at the seed's choice; fewer
    than 32 covered tiles: no trial (it would cost half the map)."""
    Rh = 128
    h_tex = np.arange(Rh * Rh)
    h_rows, _ = ht.pick(h_tex, Rh, h_tex, Rh, seed=0)
    tiles = np.unique((h_tex[h_rows] // Rh) // ht.TILE * (Rh // ht.TILE)
                      + (h_tex[h_rows] % Rh) // ht.TILE)
    assert len(tiles) == 256 // 8 and np.all(np.diff(tiles // 8) == 1)   # one per run of 8
    again, _ = ht.pick(h_tex, Rh, h_tex, Rh, seed=0)
    other, _ = ht.pick(h_tex, Rh, h_tex, Rh, seed=1)
    assert np.array_equal(again, h_rows) and not np.array_equal(other, h_rows)
    assert ht.pick(np.arange(40 * 40), 40, np.arange(40 * 40), 40) is None     # 25 tiles


def test_the_decision_needs_a_clear_ratio_and_the_errors_are_the_checks(tmp_path):
    """The decision rule; the check at some texels (heldout_errors(texels=), what the trial
    runs) combines the errors as sqrt(sum err^2 / sum ref^2) over those texels, computed here
    from the whole images, and with every texel it is the whole check."""
    from relightable_textures.lt_addon.transport import texture as tt

    assert ht.decide(0.05, 0.09) == "horizon" and ht.decide(0.16, 0.08) == "transport"
    assert ht.decide(0.05, 0.06) is None and ht.decide(0.06, 0.05) is None
    rng = np.random.default_rng(0)
    R = 16
    dset = tt.parse_directions("hemi:48:1.5")
    store = tt.TransportStore.create(str(tmp_path / "T.npy"), dset, R)
    store.write_rows(0, rng.random((dset.size, R * R)).astype(np.float32) / np.pi)
    n = rng.standard_normal((R, R, 3))
    n[..., 2] = np.abs(n[..., 2])
    hm = hmap.HorizonMap(rng.integers(0, 256, (2, 12, R // 2, R // 2), dtype=np.uint8),
                         n.astype(np.float16))
    D = np.array([direction_from_az_el(10, 5), direction_from_az_el(200, 40)])
    ref = rng.random((2, R * R))
    texels = np.sort(rng.choice(R * R, 60, replace=False))
    e = hmap.heldout_errors(hm, store, D, ref[:, texels], 2.0, texels=texels)
    got = {"horizon": [hm.direct(d, 2.0).reshape(-1)[texels] for d in D],
           "transport": [store.relight(*tt.sun_weights(dset, d, 2.0)).reshape(-1)[texels]
                         for d in D]}
    den = sum(np.sum(r[texels] ** 2) for r in ref)
    for k, imgs in got.items():
        want = np.sqrt(sum(np.sum((g - r[texels]) ** 2) for g, r in zip(imgs, ref)) / den)
        assert abs(e[k] - want) < 1e-12 * want, k
    assert e["transport"] != e["horizon"]
    assert [r["elevation"] for r in e["directions"]] == [5.0, 40.0]
    whole = hmap.heldout_errors(hm, store, D, ref, 2.0)
    every = hmap.heldout_errors(hm, store, D, ref, 2.0, texels=np.arange(R * R))
    assert whole["horizon"] == every["horizon"] and whole["transport"] == every["transport"]
    store.abort()


def test_the_map_read_at_some_texels_is_the_whole_image_there():
    """HorizonMap.direct(texels=...) (the trial reads the map only at its texels: at 2048^2 the
    whole image per held-out sun took most of the trial's time) equals the whole image there,
    bit for bit, with the horizons at the texture's side and at a coarser one."""
    rng = np.random.default_rng(5)
    for Rh, R in ((16, 16), (16, 40), (8, 64)):
        q = rng.integers(0, 256, (2, 12, Rh, Rh), dtype=np.uint8)
        n = rng.standard_normal((R, R, 3))
        n[..., 2] = np.abs(n[..., 2])
        hm = hmap.HorizonMap(q, n.astype(np.float16))
        texels = rng.choice(R * R, R * R // 3, replace=False)
        for az, el in ((10, 3), (95, 12), (200, 40), (359, 70)):
            d = direction_from_az_el(az, el)
            whole = hm.direct(d, 2.0).reshape(-1)
            assert np.array_equal(hm.direct(d, 2.0, texels), whole[texels]), (Rh, R, az)
        assert np.array_equal(hmap.upsample_at(q[:, 3], R, texels),
                              hmap.upsample(q[:, 3], R).reshape(2, -1)[:, texels])
