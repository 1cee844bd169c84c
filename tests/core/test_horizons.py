"""Per-texel horizons (lt_addon/rays/horizon.py) and the horizon map
(lt_addon/transport/horizon_map.py) against independent computations: the analytic horizon of a
wall, the area of a disc's segment by counting, T's own rays at its directions, and a file round
trip."""

import numpy as np
import pytest

from relightable_textures.lt_addon.errors import InputError
from relightable_textures.lt_addon.rays import engine, horizon
from relightable_textures.lt_addon.rays.direct import direct_rows
from relightable_textures.lt_addon.transport import horizon_map as hmap
from relightable_textures.lt_addon.transport import texture as tt
from floor_points import floor_points

needs_engine = pytest.mark.skipif(not engine.available()[0], reason="embreex not installed")


def _floor_mesh(extra):
    """A 4 m floor (two triangles) and the quads ``extra`` (vertices (4k, 3)): (V, T)."""
    floor = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    V = np.concatenate([floor, extra])
    q = np.arange(1, len(V) // 4)[:, None] * 4
    return V, np.concatenate([[[0, 1, 2], [0, 2, 3]], q + [0, 1, 2], q + [0, 2, 3]])


def _floor_points(n, seed, extra, x=(-1.9, 0.9)):
    """Points on a 4 m floor (z = 0) under the triangles ``extra`` (vertices (4k, 3), quads):
    (occluder, shading points, positions)."""
    V, T = _floor_mesh(extra)
    occ = engine.Occluder(V, T)
    rng = np.random.default_rng(seed)
    P = np.column_stack([rng.uniform(*x, n), rng.uniform(-1.9, 1.9, n), np.zeros(n)])
    return occ, floor_points(V, T, P), P


def _floor_and_wall(n=300, seed=3):
    """Floor points in front of a wall 1.5 m high along x = 1 (|y| < 10 m)."""
    wall = np.array([[1, -10, 0], [1, 10, 0], [1, 10, 1.5], [1, -10, 1.5]], float)
    return _floor_points(n, seed, wall)


#: Half the widest bisection bracket (13 degrees / 2^7), plus the origin's self-intersection
#: push (EPSILON * 2 m up, seen from 0.1-3 m away) and float32 rays, plus the float16 the
#: edges are kept in (half of 2^-10 rad in [1, 2) rad).
TOL = np.radians(13.0 / 2 ** horizon.REFINE) / 2 + 1e-4 + 2.0 ** -11


@needs_engine
def test_the_horizon_of_a_wall_is_its_analytic_elevation():
    """Along azimuth phi (|phi| < 90 degrees) a floor point at x sees the wall's top at
    elevation atan(1.5 cos(phi) / (1 - x)), blocked from the horizon up; away from the wall
    the sky is open: an empty interval."""
    occ, pts, P = _floor_and_wall()
    A = 16
    H = horizon.horizons(occ, pts, azimuths=A)
    assert H.shape == (2, A, len(P)) and H.dtype == np.float16
    for a in range(A):
        phi = 2 * np.pi * a / A
        if np.cos(phi) > 0.05:
            assert np.all(H[0, a] == np.float16(horizon.FROM_BELOW))
            want = np.arctan(1.5 * np.cos(phi) / (1 - P[:, 0]))
            assert np.abs(H[1, a] - want).max() <= TOL, a
        elif np.cos(phi) < -0.05:      # open: the empty interval [0, 0]
            assert np.all(H[:, a] == 0)
    # every ray counted: the scan for all, the bisections only where an edge lies
    assert occ.rays <= horizon.cost(len(P), A)


@needs_engine
def test_a_floating_roof_blocks_an_interval_a_low_sun_shines_under():
    """A 1 m roof at z = 1 over 0 < x < 1 (|y| < 10 m): along +x a floor point at x < 0 is
    blocked between atan(1 / (1 - x)) and atan(1 / -x) and sees the sky below and above."""
    roof = np.array([[0, -10, 1], [1, -10, 1], [1, 10, 1], [0, 10, 1]], float)
    occ, pts, P = _floor_points(200, 4, roof, x=(-1.9, -0.2))
    H = horizon.horizons(occ, pts, azimuths=8)
    lo = np.arctan(1 / (1 - P[:, 0]))
    hi = np.arctan(1 / -P[:, 0])
    assert np.abs(H[0, 0] - lo).max() <= TOL and np.abs(H[1, 0] - hi).max() <= TOL
    hm = hmap.from_points(H, np.arange(len(P)), 15, pts.Ns)
    for el_deg in (5.0, 60.0):        # a low sun under the roof lights every point; ...
        d = horizon._dirs(0.0, np.radians(el_deg))
        want = direct_rows(occ, pts, d[None])[0]
        got = hm.direct(d).reshape(-1)[:len(P)]
        assert np.abs(got - want).max() < 1e-3
    mid = horizon._dirs(0.0, 0.5 * (lo + hi))        # ... between the edges, none of them
    # (a point sun is a disc of 1e-4 rad: its side strips read the next azimuth with a
    # weight ~1e-4, 1e-5 of light where the lit points get ~0.3)
    assert all(hm.direct(m).reshape(-1)[i] < 3e-5 for i, m in enumerate(mid))


def test_disc_fraction_is_the_area_of_the_segment():
    rng = np.random.default_rng(0)
    r = np.sqrt(rng.uniform(0, 1, 400_000))
    a = rng.uniform(0, 2 * np.pi, 400_000)
    y = r * np.sin(a)                      # points uniform in the unit disc
    for t in (-1.0, -0.7, -0.2, 0.0, 0.35, 0.9, 1.0):
        # the sun's centre t radii above the line: the part above is y > -t
        assert abs(horizon.disc_fraction(t) - np.mean(y > -t)) < 3e-3
    assert horizon.disc_fraction(-3.0) == 0.0 and horizon.disc_fraction(2.0) == 1.0


@needs_engine
def test_the_map_relights_the_rays_of_its_directions():
    """At any hard-sun direction, the map's relight is T's ray-traced row, up to the texels
    where the 8-bit horizon (0.25-0.49 degree steps) crosses the sun, or the sun's elevation lies
    between the edges at the two azimuths around it (the visibility is linear between them:
    64 azimuths, 5.6 degrees apart, measured 1.9 % of the pairs)."""
    occ, pts, P = _floor_and_wall(n=400)
    A = 64
    H = horizon.horizons(occ, pts, azimuths=A)
    R = 20
    hm = hmap.from_points(H, np.arange(len(P)), R, pts.Ns)
    assert hm.q.shape == (2, A, R, R) and hm.normals.dtype == np.float16
    rng = np.random.default_rng(1)
    D = horizon._dirs(rng.uniform(-1.2, 1.2, 40), rng.uniform(0.05, 1.4, 40))
    T = direct_rows(occ, pts, D)
    flips = 0
    for s, d in enumerate(D):
        got = hm.direct(d).reshape(-1)[:len(P)]
        differ = np.abs(got - T[s]) > 1e-3
        flips += int(differ.sum())
        # where they agree, they agree to the half-float normal's precision
        assert np.allclose(got[~differ], T[s][~differ], atol=1e-3)
    assert flips <= 0.03 * D.shape[0] * len(P), flips
    # a disc of 10 degrees: between the two hard suns at its edges
    d = horizon._dirs(0.0, np.radians(45))
    soft = hm.direct(d, 10.0).reshape(-1)[:len(P)]
    lo = hm.direct(horizon._dirs(0.0, np.radians(40))).reshape(-1)[:len(P)]
    hi = hm.direct(horizon._dirs(0.0, np.radians(50))).reshape(-1)[:len(P)]
    # (lit: beyond the 1e-4 a hard sun's strips read from the next azimuth, as above; the
    # side strips cut the whole disc by their azimuth's edge, which the wall lowers away from
    # its normal: a little light where the disc's top is blocked at the sun's azimuth)
    lit_lo, lit_hi = lo > 1e-3, hi > 1e-3
    assert np.all(soft[lit_lo] > 0) and np.all(soft[~lit_hi] <= 0.01 * soft.max())
    # an edge strictly inside the disc (not on its rim, where a code may fall exactly) cuts it
    partial = ((hm.direct(horizon._dirs(0.0, np.radians(49.5))).reshape(-1)[:len(P)] > 1e-3)
               & ~(hm.direct(horizon._dirs(0.0, np.radians(40.5))).reshape(-1)[:len(P)] > 1e-3))
    assert partial.sum() > 5 and np.all((soft[partial] > 0) & (soft[partial] < hi[partial]))
    # against 256 hard suns by rays over the disc (at three azimuths to the wall): within 2 %
    # (measured 0.7 / 1.0 / 1.2 %)
    for az in (0.0, 0.6, 1.2):
        d = horizon._dirs(az, np.radians(45))
        ref = direct_rows(occ, pts, tt._disc_points(d, np.radians(5), 256)).mean(0)
        got = hm.direct(d, 10.0).reshape(-1)[:len(P)]
        assert np.sqrt(np.mean((got - ref) ** 2) / np.mean(ref ** 2)) < 0.02, az


def test_quantize_and_margin_fill():
    H = np.array([[[-np.pi / 2, 0.001, np.pi / 4, 3.0]], [[0.0, np.pi / 4, np.pi / 2, 3.0]]])
    q = hmap.quantize(H)
    z, mid = hmap.CODE_ZERO, int(hmap.quantize(np.full((2, 1), np.pi / 4))[1, 0])
    assert q.tolist() == [[[0, z, mid, 255]], [[z, mid, 255, 255]]]
    assert np.allclose(hmap.decode(q)[0, 0], [-np.pi / 2, 0.0, hmap.decode(q)[1, 0, 1],
                                              np.pi / 2])
    # the horizon is a code exactly; the ground's edges under it down to -10 degrees in
    # 1-degree steps, 0.25 at the horizon widening to 0.49 at the zenith: each edge within
    # half a step of its code, and the decoding continuous (the viewport interpolates codes)
    assert hmap.decode(q)[1, 0, 0] == 0.0 and hmap.EDGE_MIN <= horizon.BELOW
    e = np.radians(np.linspace(-10, 90, 2001))
    back = hmap.decode(hmap.quantize(np.stack([np.zeros_like(e), e])))[1]
    half = np.where(e < 0, hmap.STEP_BELOW, hmap.STEP_HORIZON + np.sqrt(
        4 * hmap.CURVE * np.maximum(e, 0))) / 2
    assert np.all(np.abs(back - e) <= half + 1e-9)
    assert np.degrees(hmap.STEP_HORIZON) == 0.25 and 0.48 < np.degrees(hmap.STEP) < 0.5
    x = np.linspace(0, 255, 25501)
    assert np.max(np.abs(np.diff(hmap.decode(np.stack([x, x]))[1]))) <= hmap.STEP_BELOW / 99
    import scipy.sparse as sps

    # margin texel 4 = mean of points 0 and 1; texel 5 = mean of points 2 and 3; texel 6 =
    # mean of points 0 and 4, the latter a face turned away from the one azimuth (+x): its
    # interval, open for want of a cosine, is left out (the mean would open the sky above 0.1)
    op = sps.csr_matrix(np.array([[0.5, 0.5, 0.0, 0.0, 0.0], [0.0, 0.0, 0.5, 0.5, 0.0],
                                  [0.5, 0.0, 0.0, 0.0, 0.5]]))
    N = np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0]])
    H = np.array([[[-np.pi / 2, -np.pi / 2, 0.2, 0.4, 0.0]], [[0.2, 0.4, 0.6, 0.8, 0.0]]])
    hm = hmap.from_points(H, np.array([0, 1, 2, 3, 4]), 3, N, (np.array([5, 6, 7]), op))
    h = hmap.decode(hm.q).reshape(2, -1)
    assert h[0, 5] == -np.pi / 2 and abs(h[0, 6] - 0.3) < hmap.STEP
    assert abs(h[1, 5] - 0.3) < hmap.STEP and abs(h[1, 6] - 0.7) < hmap.STEP
    assert np.allclose(hm.normals.reshape(-1, 3)[5], [0.7071, 0, 0.7071], atol=1e-3)
    assert h[0, 7] == -np.pi / 2 and abs(h[1, 7] - 0.2) < hmap.STEP
    # horizons at a coarser side (here the same texels) leave them out alike, given their
    # points' normals
    pts = np.array([0, 1, 2, 3, 4])
    coarse = hmap.from_points(H, pts, 3, N, coarse=(pts, 3, (np.array([5, 6, 7]), op), N))
    assert np.array_equal(coarse.q, hm.q)
    assert np.allclose(hm.normals.reshape(-1, 3)[7], [-0.7071, 0, 0.7071], atol=1e-3)
    assert np.all(hm.normals.reshape(-1, 3)[8:] == 0) and np.all(h[0, 8:] == -np.pi / 2)
    assert np.all(h[1, 8:] == 0)


def test_save_load_round_trip_and_a_newer_format_is_refused(tmp_path):
    rng = np.random.default_rng(2)
    hm = hmap.HorizonMap(rng.integers(0, 256, (2, 6, 8, 8), dtype=np.uint8),
                         rng.normal(size=(8, 8, 3)).astype(np.float16))
    path = str(tmp_path / "o_horizons.npz")
    hmap.save(path, hm)
    back = hmap.load(path)
    assert np.array_equal(back.q, hm.q) and np.array_equal(back.normals, hm.normals)
    np.savez(path, q=hm.q, normals=hm.normals, format=np.array(hmap.FORMAT),
             format_version=np.array(99))
    with pytest.raises(InputError, match="newer"):
        hmap.load(path)
    # the GPU figure: 2 x 6 azimuths in four 8-bit RGBA tiles (2 x 2 grid of 8 + 2 texel
    # strides), normals and albedo in two half-float RGBA tiles (2 x 1); with the edges'
    # spreads six tiles (3 x 2)
    assert hmap.gpu_bytes(6, 8) == 20 * 20 * 4 + 20 * 10 * 8
    assert hmap.gpu_bytes(6, 8, spread=True) == 30 * 20 * 4 + 20 * 10 * 8
    assert hm.gpu_bytes() == hmap.gpu_bytes(6, 8)
    # a map with spreads keeps them (a version-2 map, without, reads as sharp edges)
    hs = hmap.HorizonMap(hm.q, hm.normals, rng.integers(0, 256, (6, 8, 8), dtype=np.uint8))
    hmap.save(path, hs)
    back = hmap.load(path)
    assert np.array_equal(back.spread, hs.spread)
    assert back.gpu_bytes() == hmap.gpu_bytes(6, 8, spread=True)
    np.savez(path, q=hm.q, normals=hm.normals, spread=hs.spread[:, :4],
             format=np.array(hmap.FORMAT), format_version=np.array(3))
    with pytest.raises(InputError, match="spread"):
        hmap.load(path)
    # a map with open bands (four planes of codes: 2 x 6 azimuths more, eight tiles in a 3 x 3
    # grid) keeps them; four planes in a file older than format 5, or three, are refused
    hg = hmap.HorizonMap(rng.integers(0, 256, (4, 6, 8, 8), dtype=np.uint8), hm.normals)
    assert hg.gaps and not hm.gaps
    assert hg.gpu_bytes() == hmap.gpu_bytes(6, 8, gaps=True) == 30 * 30 * 4 + 20 * 10 * 8
    hmap.save(path, hg)
    assert np.array_equal(hmap.load(path).q, hg.q)
    for q, version in ((hg.q, 4), (hg.q[:3], 5)):
        np.savez(path, q=q, normals=hm.normals, format=np.array(hmap.FORMAT),
                 format_version=np.array(version))
        with pytest.raises(InputError, match="horizon codes"):
            hmap.load(path)


def test_band_spreads_survive_the_file_and_are_refused_without_bands_or_before_format_7(
        tmp_path):
    """``band_spread`` (2, A, Rh, Rh) uint8 is written and read back with a banded map (the GPU
    figure: two sets of tiles more); in a format-6 file, or beside two planes of codes, it is
    refused in one line; without its bands (the hull) or with its edges sharp it is gone."""
    rng = np.random.default_rng(4)
    q = rng.integers(0, 256, (4, 6, 8, 8), dtype=np.uint8)
    n = rng.normal(size=(8, 8, 3)).astype(np.float16)
    bs = rng.integers(0, 256, (2, 6, 8, 8), dtype=np.uint8)
    hb = hmap.HorizonMap(q, n, band_spread=bs)
    path = str(tmp_path / "o_horizons.npz")
    hmap.save(path, hb)
    back = hmap.load(path)
    assert np.array_equal(back.band_spread, bs) and np.array_equal(back.q, q)
    assert back.gpu_bytes() == hmap.gpu_bytes(6, 8, gaps=True, band_spread=True) > \
        hmap.gpu_bytes(6, 8, gaps=True)
    assert back.without_bands().band_spread is None and back.without_band_spread().band_spread \
        is None and np.array_equal(back.without_crossings().band_spread, bs)
    for qq, version in ((q, 6), (q[:2], 7)):
        np.savez(path, q=qq, normals=n, band_spread=bs, format=np.array(hmap.FORMAT),
                 format_version=np.array(version))
        with pytest.raises(InputError, match="band spreads"):
            hmap.load(path)


def test_a_bands_edges_over_the_footprint_count_a_shut_sub_sample_at_its_middle():
    """Two pairs, the centre weighted 0.25 and three sub-samples 0.25 each: the first pair's
    sub-samples all see the band, so its means and spreads are those of the four edges; in the
    second one sub-sample is shut (behind a box's edge), so both its edges count at the
    centre's band's middle, 20 degrees: the lower edge's mean rises, the upper's falls."""
    g_lo, g_hi = np.radians([10.0, 10.0]), np.radians([30.0, 30.0])
    group = np.array([0, 0, 0, 1, 1, 1])
    lo_s = np.radians([9.0, 11.0, 10.0, 9.0, 11.0, 0.0])
    hi_s = np.radians([29.0, 31.0, 30.0, 29.0, 31.0, 0.0])
    shut = np.array([False, False, False, False, False, True])
    m_lo, m_hi, s_lo, s_hi = hmap.band_edges(g_lo, g_hi, lo_s, hi_s, shut, group,
                                            np.full(6, 0.25), np.full(2, 0.25))
    one = np.radians([10.0, 9.0, 11.0, 10.0])
    assert np.allclose(m_lo[0], one.mean()) and np.allclose(s_lo[0], one.std())
    assert np.allclose(m_hi[0], np.radians(30.0)) and np.allclose(s_hi[0], one.std())
    two_lo, two_hi = np.radians([10.0, 9.0, 11.0, 20.0]), np.radians([30.0, 29.0, 31.0, 20.0])
    assert np.allclose([m_lo[1], m_hi[1]], [two_lo.mean(), two_hi.mean()])
    assert np.allclose([s_lo[1], s_hi[1]], [two_lo.std(), two_hi.std()])


def test_the_margin_is_lit_as_cycles_extends_the_islands_light(tmp_path):
    """A map that keeps its island fills the bake's margin from the island's light, as Cycles'
    Extend margin fills a baked texture (by hand: a texel beside a straight border is
    ``(2 c + l + r) / 4`` of the three island texels it touches), not from its codes' margin,
    which averages the edges: a lit texel (open sky) beside a shadowed one (edge 60 degrees)
    gives an edge of 30 degrees, dark under a sun 3 degrees high, where Cycles' margin is half
    lit. Whole or at some texels, bit for bit; kept by a file round trip; a file's margin out
    of range (wider than the bakes' 4 texels) or an island without a texel is refused in one
    line."""
    from relightable_textures.lt_addon.rays.texels import extend_margin

    R, A = 6, 8
    island = np.zeros((R, R), bool)
    island[:, :3] = True                                # columns 0-2, margin columns 3-4
    texel = np.flatnonzero(island)
    P = len(texel)
    col = texel % R
    H = np.zeros((2, A, P))
    H[0] = -np.pi / 2                                   # blocked from below ...
    H[1] = np.where((col == 2) & (texel // R % 2 == 0), np.radians(60.0), 0.0)[None]
    N = np.tile([0.0, 0.0, 1.0], (P, 1))
    mg = extend_margin(island, 2)
    plain = hmap.from_points(H, texel, R, N, mg)
    hm = hmap.from_points(H, texel, R, N, mg, margin_texels=2)
    assert plain.island is None and hm.margin == 2 and np.array_equal(hm.island, island)
    d = horizon._dirs(0.0, np.radians(3.0))
    lit = float(np.sin(np.radians(3.0)) / np.pi)
    whole, codes = hm.direct(d, 0.526), hm.direct_codes(d, 0.526)
    assert np.array_equal(plain.direct(d, 0.526), codes)        # no island: the codes' margin
    assert np.array_equal(whole[island], codes[island])
    # rows 0, 2, 4 of column 2 are shadowed (0), rows 1, 3, 5 lit; margin column 3 of row 2
    # touches (1, 2), (2, 2), (3, 2): (lit + 2 * 0 + lit) / 4
    assert codes[2, 2] == 0.0 and abs(codes[1, 2] - lit) < 2e-3 * lit
    assert abs(whole[2, 3] - (codes[1, 2] + 2 * codes[2, 2] + codes[3, 2]) / 4) < 1e-9
    assert whole[2, 3] > 0.4 * lit and codes[2, 3] < 0.01 * lit      # the codes': dark
    assert np.all(whole[:, 5] == 0)                                  # past the margin
    some = np.array([2 * R + 3, 1 * R + 4, 7, 5, 2 * R + 2])
    assert np.array_equal(hm.direct(d, 0.526, some), whole.reshape(-1)[some])
    path = str(tmp_path / "o_horizons.npz")
    hmap.save(path, hm)
    back = hmap.load(path)
    assert back.margin == 2 and np.array_equal(back.island, island)
    assert np.array_equal(back.direct(d, 0.526), whole)
    # the bake's own operator, kept by from_points and shared without the bands, is the one
    # a loaded map builds
    assert (abs(back.extend()[2] - hm.extend()[2]).max() == 0
            and hm.without_bands().extend() is hm.extend())
    with pytest.raises(IndexError):
        hm.direct(d, 0.526, np.array([R * R]))
    z = dict(np.load(path))
    for key, value, words in (("margin", np.array(hmap.MAX_MARGIN + 1), "margin"),
                              ("island", np.zeros((R, R), np.uint8), "island")):
        np.savez(path, **{**z, key: value})
        with pytest.raises(InputError, match=words):
            hmap.load(path)


def test_pair_edges_are_the_weighted_mean_and_spread_of_the_sub_samples():
    """Two texels, two azimuths: the footprint's upper edge is the weighted mean of its
    centre's and sub-samples' edges, its spread their weighted standard deviation; an open
    sub-sample counts at its centre's lower edge (0 under one blocked from below)."""
    fb = -np.pi / 2
    Hc = np.array([[[fb, 0.3]], [[0.2, 0.5]]]).repeat(2, axis=1)         # (2, A=2, M=2)
    Hc[:, 1, 0] = [fb, 0.4]
    # texel 0: subs 0.1, 0.3, open; texel 1 (floating [0.3, 0.5]): subs 0.7, open
    Hs = np.array([[fb, fb, 0.0, 0.3, 0.2], [0.1, 0.3, 0.0, 0.7, 0.2]])[:, None, :].repeat(2, 1)
    owner = np.array([0, 0, 0, 1, 1])
    weight = np.array([0.2, 0.2, 0.2, 0.25, 0.25])
    centre = np.array([0.4, 0.5])
    for a in range(2):
        mean, spread = hmap.pair_edges(Hc[0, a], Hc[1, a], Hs[0, a], Hs[1, a], owner, weight,
                                       centre)
        for m, (edges, w) in enumerate([([Hc[1, a, 0], 0.1, 0.3, 0.0], [0.4, 0.2, 0.2, 0.2]),
                                        ([0.5, 0.7, 0.3], [0.5, 0.25, 0.25])]):
            mu = np.average(edges, weights=w)
            sd = np.sqrt(np.average((np.array(edges) - mu) ** 2, weights=w))
            assert abs(mean[m] - mu) < 1e-12 and abs(spread[m] - sd) < 1e-12


def test_a_spread_edge_relights_a_footprint_whose_edges_are_spread_over_an_interval():
    """Sub-samples whose upper edges spread evenly over [h - w, h + w] see a hard sun at
    elevation e with the fraction clamp((e - h + w) / 2w); the map of their mean edge and
    spread gives that within 0.05 at every elevation -- a disc's chord profile for a ramp
    differs from it by 0.029 at most, and the edge's code by up to half a 0.25-0.49-degree step,
    0.029 of this 6-degree ramp (measured: 0.043) --, where the mean edge alone errs by up
    to 0.5."""
    h, w = np.radians(10.0), np.radians(3.0)
    edges = np.linspace(h - w, h + w, 401)
    Hc = np.array([[[-np.pi / 2]], [[h]]])
    Hs = np.stack([np.full(401, -np.pi / 2), edges])[:, None, :]
    mean, spread = hmap.pair_edges(Hc[0, 0], Hc[1, 0], Hs[0, 0], Hs[1, 0],
                                   np.zeros(401, np.int64), np.full(401, 1 / 402),
                                   np.array([1 / 402]))
    mean, spread = mean[None], spread[None]                              # (A = 1, 1 texel)
    A, R = 3, 1
    H = np.stack([np.full((A, 1), -np.pi / 2), np.repeat(mean, A, 0)])
    sharp = hmap.from_points(H, np.array([0]), R, np.array([[0, 0, 1.0]]))
    soft = hmap.from_points(H, np.array([0]), R, np.array([[0, 0, 1.0]]),
                            spread=np.repeat(spread, A, 0))
    worst_soft = worst_sharp = 0.0
    for e in np.linspace(h - 1.5 * w, h + 1.5 * w, 61):
        d = np.array([np.cos(e), 0.0, np.sin(e)])
        want = np.clip((e - h + w) / (2 * w), 0, 1)
        cos = np.sin(e)
        worst_soft = max(worst_soft, abs(soft.direct(d)[0, 0] * np.pi / cos - want))
        worst_sharp = max(worst_sharp, abs(sharp.direct(d)[0, 0] * np.pi / cos - want))
    assert worst_soft < 0.05 and worst_sharp > 0.45, (worst_soft, worst_sharp)
    # the codes: 0 is sharp; a 1-degree spread is held to 0.03 degrees
    assert hmap.decode_spread(hmap.encode_spread(0.0)) == 0.0
    assert abs(np.degrees(hmap.decode_spread(hmap.encode_spread(np.radians(1.0)))) - 1) < 0.03


def test_varying_flags_the_texels_beside_a_jump_in_an_edge():
    """A 6 x 6 map whose upper edge jumps by 5 degrees between columns 2 and 3 at one
    azimuth: the texels of those two columns vary; a jump of half a degree does not count."""
    R, A = 6, 4
    texel = np.arange(R * R)
    H = np.zeros((2, A, R * R))
    H[0] = -np.pi / 2
    col = texel % R
    H[1, 2] = np.where(col >= 3, np.radians(15.0), np.radians(10.0))
    H[1, 1] = np.where(col >= 4, np.radians(10.5), np.radians(10.0))
    got = np.nonzero(hmap.varying_pairs(H, texel, R).any(axis=0))[0]
    assert sorted(set(col[got])) == [2, 3] and len(got) == 2 * R
    # a neighbour not yet found does not count
    found = col != 3
    assert not hmap.varying_pairs(H, texel, R, found).any()


@needs_engine
def test_a_ray_budget_splits_the_points_and_changes_no_bit(monkeypatch):
    """The scan takes its points in chunks of RAY_BUDGET / 18 elevations (4 M rays a call at
    any texture size); the intervals do not depend on the chunking."""
    roof = np.array([[0, -10, 1], [1, -10, 1], [1, 10, 1], [0, 10, 1]], float)
    occ, pts, P = _floor_points(150, 5, roof, x=(-1.9, 0.9))
    whole = horizon.horizons(occ, pts, azimuths=12)
    monkeypatch.setattr(horizon, "RAY_BUDGET", 18 * 7)       # 7 points a call
    calls = occ.rays
    parts = horizon.horizons(occ, pts, azimuths=12)
    assert np.array_equal(whole, parts) and occ.rays - calls == calls


@needs_engine
def test_chosen_pairs_find_the_intervals_the_whole_scan_finds():
    """The footprints' scan of chosen (azimuth, point) pairs (iter_pair_horizons) finds each
    pair's interval as the whole map's scan does: a floating roof and a wall over floor points
    (intervals from below and floating), 400 random pairs at 16 azimuths, in blocks of 7
    pairs; open pairs are [0, 0] (the whole map places its open ones between neighbours)."""
    roof = np.array([[0, -10, 1], [1, -10, 1], [1, 10, 1], [0, 10, 1],
                     [1.5, -10, 0], [1.5, 10, 0], [1.5, 10, 1.5], [1.5, -10, 1.5]], float)
    occ, pts, P = _floor_points(120, 7, roof, x=(-1.9, 1.4))
    A = 16
    whole, _ = _run(horizon.iter_horizons(occ, pts, A))
    rng = np.random.default_rng(1)
    ai, pi = rng.integers(0, A, 400), rng.integers(0, pts.size, 400)
    gen = horizon.iter_pair_horizons(occ, pts, A, ai, pi)
    lo, hi = _run(gen)
    found = whole[1, ai, pi] > whole[0, ai, pi]
    assert found.sum() > 150 and (~found).sum() > 20 and (whole[0, ai, pi] < -1).sum() > 50
    assert np.array_equal(lo[found], whole[0, ai, pi][found])
    assert np.array_equal(hi[found], whole[1, ai, pi][found])
    assert np.all(lo[~found] == 0) and np.all(hi[~found] == 0)
    import relightable_textures.lt_addon.rays.horizon as hz
    budget = hz.RAY_BUDGET
    try:
        hz.RAY_BUDGET = 18 * 7
        lo7, hi7 = _run(horizon.iter_pair_horizons(occ, pts, A, ai, pi))
    finally:
        hz.RAY_BUDGET = budget
    assert np.array_equal(lo7, lo) and np.array_equal(hi7, hi)


@needs_engine
def test_bracketed_edges_agree_with_the_scan_and_fall_back_to_it_outside_their_brackets():
    """Sub-samples' upper edges searched within brackets (iter_pair_edges): where the bracket
    holds the edge (the whole scan's edge -0.6 / +0.4 degrees) the edge is the scan's within
    the bisections' precision (both narrow to 0.1 degrees: TOL each), and so where the bracket
    lies 3-5 degrees above the edge (a ray over the lower terminator, then bisection); an
    open pair is the pair's whole scan, bit for bit; the pairs whose brackets hold their
    edges cast under 7 rays each on average."""
    roof = np.array([[0, -10, 1], [1, -10, 1], [1, 10, 1], [0, 10, 1],
                     [1.5, -10, 0], [1.5, 10, 0], [1.5, 10, 1.5], [1.5, -10, 1.5]], float)
    occ, pts, P = _floor_points(120, 7, roof, x=(-1.9, 1.4))
    A = 16
    rng = np.random.default_rng(3)
    ai, pi = rng.integers(0, A, 300), rng.integers(0, pts.size, 300)
    lo_w, hi_w = _run(horizon.iter_pair_horizons(occ, pts, A, ai, pi))
    found = hi_w > lo_w
    hw = hi_w.astype(np.float64)
    miss = found & (rng.random(300) < 0.2) & (hw < np.radians(80))
    lo_b = np.where(miss, hw + np.radians(3.0), hw - np.radians(0.6))
    hi_b = np.where(miss, hw + np.radians(5.0), hw + np.radians(0.4))
    lo, hi = _run(horizon.iter_pair_edges(occ, pts, A, ai, pi, lo_b, hi_b))
    inside = found & ~miss & (hw > np.radians(0.6))
    assert inside.sum() > 100 and miss.sum() > 10 and (~found).sum() > 20
    assert np.abs(hi[inside].astype(np.float64) - hw[inside]).max() < 2 * TOL
    # most took the bracket (only the upper edge is sought: "from below"); one blocked to the
    # zenith (under the roof) is the terminator's edge, as the scan has it
    took = lo < -1.5
    zenith = hw > np.radians(89.5)
    assert took[inside & ~zenith].mean() > 0.9, took[inside & ~zenith].mean()
    assert np.array_equal(hi[inside & ~took], hi_w[inside & ~took])
    z = inside & zenith
    assert np.abs(hi[z].astype(np.float64) - hw[z]).max(initial=0) < 2 * TOL
    # a bracket above the edge: a ray over the terminator finds it below, bisected there
    assert np.abs(hi[miss].astype(np.float64) - hw[miss]).max() < 2 * TOL
    # an open pair: the whole scan's, bit for bit (every ray in front cast: the same answer
    # as the scan, which skips the upward rays no caster can meet)
    back = ~found
    assert np.array_equal(hi[back], hi_w[back]) and np.array_equal(lo[back], lo_w[back])
    # a bracketed pair costs its two ends and the bisection of a 1-degree bracket (4 steps)
    k = np.nonzero(inside & ~zenith)[0]
    r0 = occ.rays
    _run(horizon.iter_pair_edges(occ, pts, A, ai[k], pi[k], lo_b[k], hi_b[k]))
    assert occ.rays - r0 <= 7 * len(k), (occ.rays - r0, len(k))


def test_a_linear_edge_takes_its_gradients_spread_and_a_jump_does_not():
    """On a 6 x 6 grid, an upper edge rising 2 degrees a texel along x and 1 along y is linear:
    its footprint's spread over a half-texel box is |(2, 1)| degrees x 0.5 / sqrt(12) -- the
    standard deviation of a linear function over a uniform box, checked by sampling the box --
    and where it jumps by 5 degrees (a rim) it is not linear: rays find that spread."""
    R, A = 6, 2
    texel = np.arange(R * R)
    row, col = texel // R, texel % R
    H = np.zeros((2, A, R * R))
    H[0] = -np.pi / 2
    H[1, 0] = np.radians(20.0 + 2.0 * col + 1.0 * row)
    H[1, 1] = np.radians(20.0 + np.where(col >= 3, 5.0, 0.0))
    inner = texel[(row > 0) & (row < R - 1) & (col > 0) & (col < R - 1)]
    nb = hmap.neighbours(texel, R)
    smooth, spread = hmap.smooth_spreads(H, nb, np.zeros(len(inner), int), inner, 0.5)
    u = np.random.default_rng(0).uniform(-0.25, 0.25, (200000, 2))
    want = np.radians(np.std(2.0 * u[:, 0] + 1.0 * u[:, 1]))
    assert smooth.all() and np.allclose(spread, want, rtol=0.01)
    smooth, _ = hmap.smooth_spreads(H, nb, np.ones(len(inner), int), inner, 0.5)
    jump = (inner % R == 2) | (inner % R == 3)
    assert not smooth[jump].any() and smooth[~jump].all()
    # an edge texel (a neighbour missing) is never taken as linear
    assert not hmap.smooth_spreads(H, nb, [0], [0], 0.5)[0][0]


def _run(gen):
    """A generator's return value."""
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value


@needs_engine
def test_the_search_finds_the_highest_and_lowest_blocked_elevations_of_a_full_scan():
    """Down from the top to the first blocked ray, then up from the bottom: the same two
    elevations as casting every one, on floor points under a floating roof with a wall
    beyond it (sky between the two along +x: a gap the hull covers), in fewer rays."""
    roof = np.array([[0, -10, 0.4], [0.6, -10, 0.4], [0.6, 10, 0.4], [0, 10, 0.4]], float)
    wall = np.array([[1.5, -10, 0], [1.5, 10, 0], [1.5, 10, 1.2], [1.5, -10, 1.2]], float)
    occ, pts, P = _floor_points(400, 6, np.concatenate([roof, wall]), x=(-1.9, -0.1))
    els = np.radians(np.asarray(horizon.ELEVATIONS))
    J, n = len(els), len(P)
    gaps = 0
    phis = (0.0, 0.4, 2.0, np.pi)
    JJ = np.arange(J)[:, None]
    tops, bottoms, casts = [], [], []
    for phi in phis:
        L = horizon._dirs(phi, els)
        cast = np.random.default_rng(1).random((J, n)) < 0.9    # some rays not needed
        full = np.stack([occ.occluded(horizon.shadow_origins(pts, L[j]),
                                      L[j].astype(np.float32)) for j in range(J)]) & cast
        rays = occ.rays
        top, bottom, cast_rays = horizon._search(occ, pts, L, L.astype(np.float32),
                                                 slice(0, n), np.arange(n), cast)
        assert np.array_equal(top, np.where(full, JJ, -1).max(0))
        assert np.array_equal(bottom, np.where(full, JJ, J).min(0))
        assert occ.rays - rays == cast_rays <= cast.sum()
        found = top >= 0
        gaps += int(np.sum(found & (full.sum(0) < top - bottom + 1)))
        if phi == 0.0:
            assert found.all() and cast_rays < 0.8 * cast.sum()
        tops.append(top), bottoms.append(bottom), casts.append(cast)
    assert gaps > 50          # the scene has the case the hull is for
    # the same search over (point, azimuth) pairs, the four azimuths in one call per
    # elevation (as the scan's blocks cast): the same answers, pair by pair
    L = np.stack([horizon._dirs(phi, els) for phi in phis], 1)           # (J, 4, 3)
    which = np.repeat(np.arange(len(phis)), n)
    rays = occ.rays
    top, bottom, cast_rays = horizon._search(occ, pts, L, L.astype(np.float32), None,
                                             np.tile(np.arange(n), len(phis)),
                                             np.concatenate(casts, 1), which=which)
    assert np.array_equal(top, np.concatenate(tops))
    assert np.array_equal(bottom, np.concatenate(bottoms))
    assert occ.rays - rays == cast_rays


def test_each_bisection_narrows_its_bracket_to_the_widest_gaps_precision():
    """Brackets as wide as the scan's gaps take the steps that bring them within 13 degrees /
    2^7 (the widest gap's after REFINE steps), no more: 4 for the 1-degree gaps at the
    horizon, 7 for the 13-degree one; none for an empty bracket."""
    gaps = np.radians(np.diff(horizon.ELEVATIONS))
    n = horizon.steps(gaps)
    tol = np.radians(13.0) / 2 ** horizon.REFINE
    assert np.all(gaps / 2.0 ** n <= tol * (1 + 1e-12))
    assert np.all(gaps / 2.0 ** (n - 1) > tol)                  # one step fewer would not do
    assert n[horizon.J0] == 4 and n.max() == horizon.REFINE and horizon.steps(0.0) == 0
    assert horizon.steps(gaps, 0).max() == 0


def _floor_grid(R, extra):
    """The texel centres of an R^2 texture on the 4 m floor of :func:`_floor_points` (UV = the
    floor's xy square): (occluder, shading points, flat texel indices)."""
    V, T = _floor_mesh(extra)
    c = (np.arange(R) + 0.5) / R * 4 - 2
    X, Y = np.meshgrid(c, c)                       # rows from v = 0: y grows with the row
    P = np.column_stack([X.ravel(), Y.ravel(), np.zeros(R * R)])
    return engine.Occluder(V, T), floor_points(V, T, P), np.arange(R * R)


@needs_engine
def test_horizons_at_half_the_side_relight_the_texture_at_its_own():
    """Horizons found at the texel centres of half the texture's side, read bilinearly at the
    texture's texels (as the viewport's linear lookup does), relight the wall's shadow against
    the rays at the texture's own texels: every texel agrees but those within a coarse texel
    of the shadow's edge: at 20 suns 6-46 degrees high, relative error 0.105 with 2.2 % of the
    texels off by more than 0.05, against 0.096 and 1.7 % for horizons at the full side (both
    mostly the 32 azimuths' interpolation)."""
    wall = np.array([[0.3, -10, 0], [0.3, 10, 0], [0.3, 10, 1.0], [0.3, -10, 1.0]], float)
    R, A = 32, 32
    occ, pts, texel = _floor_grid(R, wall)
    _, pts_h, texel_h = _floor_grid(R // 2, wall)
    full = hmap.from_points(horizon.horizons(occ, pts, A), texel, R, pts.Ns)
    half = hmap.from_points(horizon.horizons(occ, pts_h, A), texel, R, pts.Ns,
                            coarse=(texel_h, R // 2, None))
    assert half.q.shape == (2, A, R // 2, R // 2) and half.normals.shape == (R, R, 3)
    assert half.resolution == R and half.horizon_resolution == R // 2
    assert half.gpu_bytes() < full.gpu_bytes()
    rng = np.random.default_rng(4)
    D = horizon._dirs(rng.uniform(-1.4, 1.4, 20), rng.uniform(0.1, 0.8, 20))   # towards +x
    T = direct_rows(occ, pts, D)
    err = {}
    for name, hm in (("full", full), ("half", half)):
        got = np.stack([hm.direct(d).reshape(-1) for d in D])
        err[name] = (np.linalg.norm(got - T) / np.linalg.norm(T),
                     float(np.mean(np.abs(got - T) > 0.05)))
    assert (T == 0).mean() > 0.1 and (T > 0).mean() > 0.3       # shadow and light both seen
    assert err["full"][0] < 0.12 and err["full"][1] < 0.03, err
    assert err["half"][0] < 1.3 * err["full"][0] and err["half"][1] < 0.04, err
    # upsampling is the identity at the same side, and clamps at the edges
    q = rng.integers(0, 256, (2, 3, 4, 4)).astype(np.uint8)
    assert np.array_equal(hmap.upsample(q, 4), q)
    up = hmap.upsample(q, 8)
    assert np.allclose(up[..., 0, 0], q[..., 0, 0]) and np.allclose(up[..., -1, -1],
                                                                     q[..., -1, -1])
    assert hmap.side(2048) == hmap.AUTO_SIDE and hmap.side(256) == 256
    assert hmap.side(2048, 512) == 512 and hmap.side(256, 512) == 256


def test_an_animated_sun_asks_for_horizons_at_the_texture_side():
    """for_sun_path: the texture's side (at most AUTO_SIDE) and PATH_AZIMUTHS azimuths, never
    less than asked, within the GPU budget (more azimuths dropped first, then the side)."""
    big = 1 << 40
    A = hmap.PATH_AZIMUTHS
    assert hmap.for_sun_path(256, 96, 96, big) == (A, 256)
    assert hmap.for_sun_path(256, 2 * A, 0, big) == (2 * A, 256)       # more asked: kept
    assert hmap.for_sun_path(4096, 96, 256, big) == (A, hmap.AUTO_SIDE)
    assert hmap.for_sun_path(256, 0, 96, big) == (0, 96)                # none asked: none
    # a budget that holds 96 azimuths at 256^2 but not PATH_AZIMUTHS: the side only
    budget = hmap.gpu_bytes(96, 256, 256)
    assert hmap.gpu_bytes(A, 256, 256) > budget
    assert hmap.for_sun_path(256, 96, 96, budget) == (96, 256)
    # a budget that holds only what was asked: as asked
    tight = hmap.gpu_bytes(96, 256, 96)
    assert hmap.for_sun_path(256, 96, 96, tight) == (96, 96)


def _wall_over_floor(n=200, seed=5):
    """Points low on a wall at x = -1 facing +x (y in [-0.5, 0.5], z in [0.05, 0.5]), over the
    4 m floor: (occluder, shading points, heights z). Along +x a ray from height z at
    elevation -e meets the floor (whose edge is 3 m away) where tan e >= z / 3."""
    from relightable_textures.lt_addon.rays.shading import shading_points

    wall = np.array([[-1, -2, 0], [-1, 2, 0], [-1, 2, 1.5], [-1, -2, 1.5]], float)
    V, T = _floor_mesh(wall)
    rng = np.random.default_rng(seed)
    y, z = rng.uniform(-0.5, 0.5, n), rng.uniform(0.05, 0.5, n)
    v = z / 1.5
    u = (y + 2) / 4 - v
    bary = np.column_stack([1 - u - v, u, v])
    corner = np.stack([np.tile([0.0, 0.0, 1.0], (3, 1))] * 2 + [np.tile([1.0, 0, 0], (3, 1))] * 2)
    pts = shading_points(V, T, corner, [False] * 4, np.full(n, 2), bary)
    return engine.Occluder(V, T), pts, z


@needs_engine
def test_the_ground_under_the_horizon_is_an_upper_edge_below_zero():
    """A wall seen from above its floor: along +x its points' sky is open from the horizon up,
    and under it the floor blocks from -atan(z / 3) down (the rays above that pass the floor's
    edge). A 10-degree Sun 2 degrees high reaches 3 degrees under the horizon: the map relights
    it as rays over the disc do (256 of them), where the map without the edges under the
    horizon (every open horizontal lit below) is far off."""
    occ, pts, z = _wall_over_floor()
    A = 64
    H = horizon.horizons(occ, pts, azimuths=A)
    want = -np.arctan(z / 3.0)
    tol = np.radians(13.0 / 2 ** horizon.REFINE_BELOW) / 2 + 2e-4
    assert np.all(H[0, 0] == np.float16(horizon.FROM_BELOW))
    assert np.abs(H[1, 0].astype(np.float64) - want).max() < tol
    R = 15
    texel = np.arange(len(z))
    hm = hmap.from_points(H, texel, R, pts.Ns)
    open_ = H.copy()
    ground = (H[1] < 0) & (H[1] > H[0])
    open_[0][ground] = 0.0
    open_[1][ground] = 0.0
    hm_open = hmap.from_points(open_, texel, R, pts.Ns)
    for az in (0.0, 0.3):
        d = horizon._dirs(az, np.radians(2.0))
        ref = direct_rows(occ, pts, tt._disc_points(d, np.radians(5), 256)).mean(0)
        got = hm.direct(d, 10.0).reshape(-1)[:len(z)]
        was = hm_open.direct(d, 10.0).reshape(-1)[:len(z)]
        err = np.sqrt(np.mean((got - ref) ** 2) / np.mean(ref ** 2))
        err_open = np.sqrt(np.mean((was - ref) ** 2) / np.mean(ref ** 2))
        print(f"az {az}: map {err:.4f}, without the ground's edges {err_open:.4f}")
        assert err < 0.03 and err_open > 3 * err, (err, err_open)


@needs_engine
def test_a_wide_low_sun_lights_the_visible_part_of_its_disc_at_that_parts_height():
    """A floor behind a wall 0.1 m high, a 10-degree Sun 4 and 6 degrees high: where the wall
    hides the disc's lower part, the visible upper part is higher than the disc's centre and
    lights the floor more than the centre's cosine says. The map's relight with the visible
    part's first moment is within 0.02 of 400 hard suns by rays over the disc (measured 0.010
    / 0.007); with the centre's cosine it errs over 10 times that (0.29 / 0.13). A 2-degree
    Sun gains less (0.043 -> 0.030 at 4 degrees)."""
    wall = np.array([[1, -10, 0], [1, 10, 0], [1, 10, 0.1], [1, -10, 0.1]], float)
    occ, pts, P = _floor_points(400, 3, wall)
    H = horizon.horizons(occ, pts, azimuths=64)
    hm = hmap.from_points(H, np.arange(len(P)), 21, pts.Ns)
    for el, sun, most, gain in ((4.0, 10.0, 0.02, 10), (6.0, 10.0, 0.02, 10),
                                (4.0, 2.0, 0.035, 1.2)):
        d = horizon._dirs(0.2, np.radians(el))
        ref = direct_rows(occ, pts, tt._disc_points(d, np.radians(sun / 2), 400)).mean(0)
        err = [np.sqrt(np.mean((hm.direct(d, sun, moments=m).reshape(-1)[:len(P)] - ref) ** 2)
                       / np.mean(ref ** 2)) for m in (True, False)]
        print(f"el {el}, {sun}-degree Sun: moments {err[0]:.4f}, centre {err[1]:.4f}")
        assert 0.1 < (ref > 0).mean() < 0.99                  # a penumbra, not all dark or lit
        assert err[0] < most and err[1] > gain * err[0], (el, sun, err)


def test_held_out_suns_lie_on_an_animated_suns_path():
    """With the Sun's path in the set, the held-out directions the viewport is chosen by are
    midway between its consecutive samples (the Sun the preview shows moves along it), at
    least 1 degree high, spread along it; a jump between two days' arcs is not a midpoint."""
    def arc(az0, n):
        el = np.radians(np.linspace(-2, 40, n))
        az = np.radians(az0 + np.linspace(0, 90, n))
        return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    path = np.concatenate([arc(60, 85), arc(80, 85)])
    D = hmap.heldout_directions(16, 0, path)
    assert D.shape == (16, 3) and np.allclose(np.linalg.norm(D, axis=1), 1.0)
    # each midway between its two nearest samples, half a step from each
    near = np.sort(np.arccos(np.clip(D @ path.T, -1, 1)), axis=1)[:, :2]
    step = np.arccos(np.clip(np.einsum("ij,ij->i", path[:-1], path[1:]), -1, 1))[:84].max()
    assert np.allclose(near[:, 0], near[:, 1], atol=1e-7) and np.all(near < 0.51 * step)
    assert np.all(D[:, 2] >= np.sin(np.radians(1.0)) - 1e-12)
    assert np.degrees(np.arcsin(D[:, 2])).max() > 30           # spread along the path
    # without a path (or too short a one above 1 degree): the sky's, as before
    sky = hmap.heldout_directions(16, 0)
    assert np.array_equal(hmap.heldout_directions(16, 0, path[:3]), sky)


def test_the_grounds_edges_count_only_under_a_centre_blocked_from_below():
    """A footprint under an overhang (the centre's interval floating at [2, 5] degrees) whose
    sub-samples see the caster or only the ground under the horizon: the ground's sub-samples
    count as open (at the centre's lower edge), so the mean edge stays over it and the shadow
    stays (averaging their -3 degrees in would empty the interval). Under a centre that sees
    only the ground, the sub-samples' ground edges are edges, an open one at EDGE_MIN."""
    d = np.radians
    w = np.full(4, 0.2)
    group = np.zeros(4, np.int64)
    lo_s = np.full(4, -np.pi / 2)
    hi_s = d(np.array([5.0, 5.0, -3.0, -3.0]))
    mean, _ = hmap.pair_edges([d(2.0)], [d(5.0)], lo_s, hi_s, group, w, [0.2])
    assert abs(mean[0] - d(0.2 * 5 * 3 + 0.2 * 2 * 2)) < 1e-12        # 3.8 degrees
    lo_s = np.array([-np.pi / 2, -np.pi / 2, 0.0, -np.pi / 2])
    hi_s = d(np.array([-4.0, -2.0, 0.0, -3.0]))                          # one open: [0, 0]
    mean, _ = hmap.pair_edges([-np.pi / 2], [d(-2.0)], lo_s, hi_s, group, w, [0.2])
    want = 0.2 * (d(-2.0) + d(-4.0) + d(-2.0) + hmap.EDGE_MIN + d(-3.0))
    assert abs(mean[0] - want) < 1e-12
    # a bracket for a caster's edge takes no ground's edge from a neighbour
    H = np.zeros((2, 1, 2))
    H[:, 0, 0] = [d(2.0), d(5.0)]
    H[:, 0, 1] = [-np.pi / 2, d(-3.0)]
    nb = np.array([[1, -1], [-1, 0], [-1, -1], [-1, -1]])
    lo_b, hi_b = hmap.brackets(H, nb, [0, 0], [0, 1])
    assert abs(lo_b[0] - (d(5.0) - hmap.BRACKET_MARGIN)) < 1e-12
    assert abs(lo_b[1] - (d(-3.0) - hmap.BRACKET_MARGIN)) < 1e-12
    assert abs(hi_b[1] - (d(5.0) + hmap.BRACKET_MARGIN)) < 1e-12


def _window_wall(n=400, seed=7):
    """Floor points in front of a wall 3 m high along x = 1 (|y| < 10 m) with a window
    |y| < 0.8, 0.6 < z < 1.4: (occluder, shading points, positions)."""
    quads = np.array([[[1, -10, 0], [1, 10, 0], [1, 10, 0.6], [1, -10, 0.6]],
                      [[1, -10, 1.4], [1, 10, 1.4], [1, 10, 3], [1, -10, 3]],
                      [[1, -10, 0.6], [1, -0.8, 0.6], [1, -0.8, 1.4], [1, -10, 1.4]],
                      [[1, 0.8, 0.6], [1, 10, 0.6], [1, 10, 1.4], [1, 0.8, 1.4]]], float)
    # (at least 0.5 m from the wall: nearer, the wall over the window can fall between two
    # scanned elevations -- 77 and 90 degrees -- and the scan miss it)
    return _floor_points(n, seed, quads.reshape(-1, 3), x=(-1.9, 0.5))


@needs_engine
def test_a_window_is_an_open_band_inside_the_walls_interval():
    """Along +x a floor point at distance w from a wall with a window sees the wall from the
    horizon to the sill's atan(0.6 / w), the sky to the lintel's atan(1.4 / w), the wall again
    to its top's atan(3 / w): the hull is [from below, atan(3 / w)] and the open band inside it
    the window's, both edges within the scan's precision (points whose ray along +x passes the
    window, |y| < 0.8); beside the window, no band. Without ``gaps`` the intervals are the same
    hull."""
    occ, pts, P = _window_wall()
    H = horizon.horizons(occ, pts, azimuths=16)
    gen = horizon.iter_horizons(occ, pts, 16, gaps=True)
    G, figures = _run(gen)
    assert G.shape == (4, 16, len(P)) and figures["gap_rays"] > 0
    assert np.array_equal(G[:2], H)
    w = 1.0 - P[:, 0]
    through = np.abs(P[:, 1]) < 0.78
    beside = np.abs(P[:, 1]) > 0.82
    top = np.arctan(3.0 / w)
    assert np.all(G[0, 0] == np.float16(horizon.FROM_BELOW))
    assert np.abs(G[1, 0].astype(np.float64) - top).max() < TOL
    g_lo, g_hi = G[2, 0].astype(np.float64), G[3, 0].astype(np.float64)
    assert np.abs(g_lo[through] - np.arctan(0.6 / w[through])).max() < TOL
    assert np.abs(g_hi[through] - np.arctan(1.4 / w[through])).max() < TOL
    assert np.all(g_hi[beside] <= g_lo[beside])


@needs_engine
def test_a_band_narrower_than_the_scans_step_is_found_at_its_midpoint(monkeypatch):
    """A slit 0.38 < z < 0.44 in a wall 1 m away along +x: points 0.98-1.02 m from it see the
    sky at 20.4-24.2 degrees, between the scan's 20 and 25 (both blocked). The band search
    also casts the midpoints of the scan's steps wider than GAP_STEP (22.5 here): the slit
    is found, both edges within the scan's precision; without the midpoints it is missed (the
    hull alone: a window seen past a box's top from across a room)."""
    wall = np.array([[[1, -10, 0], [1, 10, 0], [1, 10, 0.38], [1, -10, 0.38]],
                     [[1, -10, 0.44], [1, 10, 0.44], [1, 10, 3], [1, -10, 3]]], float)
    occ, pts, P = _floor_points(100, 5, wall.reshape(-1, 3), x=(-0.02, 0.02))
    w = 1.0 - P[:, 0]
    lo, hi = np.arctan(0.38 / w), np.arctan(0.44 / w)
    assert np.degrees(lo).min() > 20.0 and np.degrees(hi).max() < 25.0
    G, _ = _run(horizon.iter_horizons(occ, pts, 16, gaps=True))
    assert np.abs(G[2, 0].astype(np.float64) - lo).max() < TOL
    assert np.abs(G[3, 0].astype(np.float64) - hi).max() < TOL
    monkeypatch.setattr(horizon, "GAP_STEP", 90.0)
    G, _ = _run(horizon.iter_horizons(occ, pts, 16, gaps=True))
    assert np.all(G[3, 0] <= G[2, 0])


@needs_engine
def test_the_map_lights_a_sun_through_a_window_as_rays_do():
    """A 2-degree Sun 25 degrees high through the window lights a patch of the floor: the
    map with the open bands (128 azimuths) relights it within 0.1 of 256 hard suns by rays
    over the disc (measured 0.083 / 0.079); the hull alone (the map before the bands) leaves
    the floor dark (1.0). What is left is the patch's sides, the window's jambs: vertical
    edges, whose shadows the map draws between two azimuths (64 azimuths: 0.237 / 0.091; 256:
    0.068 / 0.061)."""
    occ, pts, P = _window_wall(900, 11)
    G, _ = _run(horizon.iter_horizons(occ, pts, 128, gaps=True))
    texel = np.arange(len(P))
    hm = hmap.from_points(G, texel, 30, pts.Ns)
    hull = hmap.from_points(G[:2], texel, 30, pts.Ns)
    assert hm.gaps and not hull.gaps and hm.gpu_bytes() > hull.gpu_bytes()
    for az in (0.05, -0.2):
        d = horizon._dirs(az, np.radians(25.0))
        ref = direct_rows(occ, pts, tt._disc_points(d, np.radians(1.0), 256)).mean(0)
        assert 0.05 < (ref > 0).mean() < 0.6                 # a patch, not all lit or dark
        err = [np.sqrt(np.mean((m.direct(d, 2.0).reshape(-1)[:len(P)] - ref) ** 2)
                       / np.mean(ref ** 2)) for m in (hm, hull)]
        print(f"az {az}: bands {err[0]:.4f}, hull {err[1]:.4f}")
        assert err[0] < 0.1 and err[1] > 0.9, err


def test_a_band_up_to_a_spread_upper_edge_lights_at_most_the_whole_disc():
    """A band reaching the interval's upper edge, that edge spread over the footprint (cut by
    a 3-degree disc where the band is cut by the sun's 1-degree one): the visible part is at
    most the whole disc (it came to 1.12 unclamped), the NumPy relight and the node tree alike
    (the twin test renders the latter)."""
    d = np.radians
    H = np.array([-np.pi / 2, d(30.3), d(20.0), d(30.3)]).reshape(4, 1, 1, 1) * np.ones(
        (4, 8, 1, 1))
    spread = hmap.encode_spread(np.full((8, 1, 1), np.sqrt((d(1.5) ** 2 - d(0.5) ** 2) / 4)))
    hm = hmap.HorizonMap(hmap.quantize(H), np.array([[[0, 0, 1.0]]], np.float16), spread)
    for el in (29.5, 30.0, 30.3, 31.0):
        sun = horizon._dirs(0.1, d(el))
        got = float(hm.direct(sun, 2.0)[0, 0])
        assert got <= np.sin(d(el + 1.0)) / np.pi + 1e-6, el


def test_a_wide_low_sun_lights_only_the_part_of_its_disc_in_front_of_the_surface():
    """The disc clipped at the surface's terminator, as each of Cycles' rays is. Over open
    sky (one texel, every azimuth open) the map's relight equals ``max(0, N . w)`` averaged
    over 4,000 directions spread over the disc, within 1 % (measured 0.2 %, 0.6 % where a
    sliver of the disc is lit), for a floor under a 10-degree Sun 1-3 degrees high, a face
    tilted 8 degrees away from the sun, a face tilted down towards a high sun (lit only under
    its terminator) and one facing the sun (no clip).
    Without the clip the floor got 0.62 / 0.87 / 0.96 of the light at 1 / 2 / 3 degrees (the
    disc's part under the floor counted with a negative cosine), and the tilted face was dark
    while its terminator was above the disc's centre."""
    def face(nx, nz):
        H = np.zeros((2, 32, 1, 1))                                        # open sky
        n = np.array([[[nx, 0.0, nz]]]) / np.hypot(nx, nz)
        return hmap.HorizonMap(hmap.quantize(H), n.astype(np.float16)), n[0, 0].astype(
            np.float16).astype(np.float64)
    t8, t5 = np.radians(8.0), np.radians(5.0)
    cases = [((0.0, 1.0), el, 10.0) for el in (1.0, 2.0, 3.0)] + [
        ((-np.sin(t8), np.cos(t8)), el, 10.0) for el in (5.0, 8.0, 11.0)] + [
        ((np.cos(t5), -np.sin(t5)), el, 10.0) for el in (81.0, 85.0, 88.0)] + [
        ((1.0, 0.3), 2.0, 10.0), ((0.0, 1.0), 0.5, 2.0)]
    for (nx, nz), el, sun in cases:
        hm, n = face(nx, nz)
        d = horizon._dirs(0.0, np.radians(el))
        w = tt._disc_points(d, np.radians(sun / 2), 4000)
        want = np.maximum(w @ n, 0.0).mean() / np.pi
        got = float(hm.direct(d, sun)[0, 0])
        assert want > 1e-4 and abs(got - want) <= 0.01 * want, ((nx, nz), el, got, want)


def test_the_clipped_disc_is_cut_by_the_intervals_edges_as_rays_over_it_are():
    """The disc clipped at the terminator and cut by the interval's edges, where the clamp
    binds and where it does not: a floor and a wall over the ground (its edge 2 degrees under
    the horizon) under a 10-degree Sun 1 and 3 degrees high; a face tilted 8 degrees away,
    its interval up to 5 degrees (under its terminator: the clamp binds) or 10 (over it),
    the Sun 9 and 12 degrees high. Within 1 % of ``max(0, N . w)`` over 4,000 directions of
    the disc, those under the interval's edges dark (measured 0.2 % at most); the tilted face
    within 2.5 % (measured 2.0 % at 9 degrees: near its terminator the cosine's change across
    the disc's azimuths, which the relight's cosine linear in elevation leaves out, is a few
    percent of it). A sun whose centre has set is dark, as in every relight (under a floating
    interval the map keeps no ground: docs/bench/2026-12-gallery.md)."""
    t8 = np.radians(8.0)
    tilted = (-np.sin(t8), 0.0, np.cos(t8))
    low, high = (3.0, 1.0), (9.0, 12.0)
    for n, lo, hi, dark, els, tol in (
            ((0.0, 0.0, 1.0), 0.0, 0.0, 0.0, low, 0.01),
            ((1.0, 0.0, 0.0), -np.pi / 2, np.radians(-2.0), np.radians(-2.0), low, 0.01),
            (tilted, -np.pi / 2, np.radians(5.0), np.radians(5.0), high, 0.025),
            (tilted, -np.pi / 2, np.radians(10.0), np.radians(10.0), high, 0.025)):
        H = np.zeros((2, 32, 1, 1))
        H[0], H[1] = lo, hi
        q = hmap.quantize(H)
        hm = hmap.HorizonMap(q, np.array([[n]], np.float16))
        lo_q, hi_q = hmap.decode(q)[:, 0, 0, 0]
        for el in els:
            d = horizon._dirs(0.0, np.radians(el))
            w = tt._disc_points(d, np.radians(5.0), 4000)
            e = np.arcsin(np.clip(w[:, 2], -1, 1))
            seen = (e > dark) & ~((e > lo_q) & (e < hi_q))
            want = (np.maximum(w @ np.array(n, float), 0.0) * seen).mean() / np.pi
            got = float(hm.direct(d, 10.0)[0, 0])
            assert want > 1e-3 and abs(got - want) <= tol * want, (n, el, got, want)
        assert hm.direct(horizon._dirs(0.0, np.radians(-0.5)), 10.0).max() == 0.0


def test_a_soft_upper_edge_clipped_at_the_terminator_is_continuous_and_never_negative():
    """An upper edge cut by a wider disc than the sun's (its spread over the footprint)
    crossing the lit range's bounds: the visible part moves continuously (no jump where the
    clamp starts to bind) and stays within [0, the lit part], for a floor-like and a
    ceiling-like lit range; sharp edges give what clamping both edges gives."""
    r, r_hi = np.radians(5.0), np.radians(15.0)
    el = np.radians(3.0)
    for lit in ((np.radians(1.0), horizon.BEYOND), (-horizon.BEYOND, np.radians(4.0))):
        a, b = lit
        whole = horizon.part_above(el, a, r) - horizon.part_above(el, b, r)
        his = np.linspace(el - 3 * r, el + 3 * r, 6001)
        v = horizon.visible_fraction(el, -np.pi / 2, his, r, r_hi, lit=lit)
        assert v.min() >= 0.0 and v.max() <= whole + 1e-12, lit
        assert np.abs(np.diff(v)).max() < 2e-3, lit           # (steps of 0.0001 rad)
        sharp = horizon.visible_fraction(el, -np.pi / 2, his, r, lit=lit)
        clamped = 1.0 - np.maximum(
            horizon.part_above(el, np.clip(-np.pi / 2, a, b), r)
            - horizon.part_above(el, np.clip(his, a, b), r), 0.0) - (1.0 - whole)
        assert np.allclose(sharp, clamped, atol=1e-12), lit
