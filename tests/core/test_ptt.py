"""Transfer tensors (Sun et al. 2007) in NumPy: the polynomial in the albedos, lighting weights,
files. Checked against brute-force loops over the terms, not against the same einsum."""

import dataclasses
import json

import numpy as np
import pytest

from relightable_textures.lt_addon.transport import ptt
from relightable_textures.lt_addon.transport.texture import parse_directions

SPECS = ("hemi:16", "hemi:8", "hemi:4")


def make(V=40, regions=2, seed=0, specs=SPECS):
    rng = np.random.default_rng(seed)
    S = [parse_directions(s).size for s in specs]
    R1 = regions + 1
    return ptt.TransferTensors(
        rng.random((S[0], V), dtype=np.float32), rng.random((S[1], 3, R1, V), dtype=np.float32),
        rng.random((S[2], 3, R1, R1, V), dtype=np.float32), specs,
        [f"M{i}" for i in range(regions)], rng.random((regions, 3)),
        rng.integers(0, R1, V).astype(np.int16), rng.random((V, 3), dtype=np.float32),
        [("a", V - 10), ("b", 10)], {"note": "synthetic"})


def brute_force(t, w, c, c_second=None, c_one=None):
    """E (V, 3) by explicit loops over directions, regions and pairs (``c_second``: the
    coefficients of a pair's second surface, ``c_one`` of the one-bounce terms; default
    ``c``)."""
    c2 = c if c_second is None else c_second
    c1 = c if c_one is None else c_one
    w0, w1, w2 = w
    E = np.zeros((t.vertices, 3))
    R1 = len(t.regions) + 1
    for ch in range(3):
        for s in range(t.direct.shape[0]):
            E[:, ch] += w0[s, ch] * t.direct[s]
        for r in range(R1):
            for s in range(t.one.shape[0]):
                E[:, ch] += c1[r, ch] * w1[s, ch] * t.one[s, ch, r]
        for a in range(R1):
            for b in range(R1):
                for s in range(t.two.shape[0]):
                    E[:, ch] += c[a, ch] * c2[b, ch] * w2[s, ch] * t.two[s, ch, a, b]
    return E


@pytest.mark.parametrize("light", [ptt.Sun((0.3, -0.2, 0.9), 3.0, 2.5, (1.0, 0.5, 0.25)),
                                   ptt.Environment(np.random.default_rng(1).random((16, 32, 3)),
                                                   "bottom_first", 40.0, 0.7)])
def test_irradiance_is_the_polynomial_in_the_albedos(light):
    t = make()
    edits = {"M0": (0.2, 0.4, 0.9)}
    w = [ptt.light_weights(d, light) for d in t.direction_sets()]
    c = t.albedos(edits)
    np.testing.assert_allclose(t.irradiance(light, edits), brute_force(t, w, c), rtol=2e-5)
    # radiance: the receiver's own (edited) colour over pi
    col = t.receiver_albedo.astype(np.float64).copy()
    col[t.receiver_region == 1] = edits["M0"]
    col[t.receiver_region == 2] = t.base_colors[1]
    np.testing.assert_allclose(t.shade(light, edits), col / np.pi * brute_force(t, w, c),
                               rtol=2e-5)


def test_albedo_scaling_is_linear_in_one_bounce_and_quadratic_in_its_own_pair():
    t = make()
    light = ptt.Sun((0.1, 0.4, 0.8))
    p = t.project(light)
    c = t.albedos({"M0": (0.3, 0.3, 0.3), "M1": (0.0, 0.0, 0.0)})
    a = 2.5
    c2 = c.copy()
    c2[1] *= a
    # only region 1 contributes besides the fixed region; separate its terms
    one = t.combine(p, c2, (1,)) - t.combine(p, c, (1,))
    own_one = np.einsum("c,cv->vc", c[1].astype(np.float32), p.one[:, 1])
    np.testing.assert_allclose(one, (a - 1) * own_one, rtol=1e-4, atol=1e-6)
    own_two = np.einsum("c,cv->vc", (c[1] ** 2).astype(np.float32), p.two[:, 1, 1])
    cross = np.einsum("c,cv->vc", c[1].astype(np.float32), p.two[:, 0, 1] + p.two[:, 1, 0])
    two = t.combine(p, c2, (2,)) - t.combine(p, c, (2,))
    np.testing.assert_allclose(two, (a * a - 1) * own_two + (a - 1) * cross, rtol=1e-4,
                               atol=1e-6)


def test_zero_weights_leave_the_direct_term():
    t = make()
    light = ptt.Sun((0.0, 0.5, 0.8))
    p = t.project(light)
    zero = np.zeros((3, 3))
    np.testing.assert_array_equal(t.combine(p, zero), t.combine(p, zero, (0,)))
    np.testing.assert_array_equal(t.combine(p, zero), t.irradiance(light, orders=(0,)))


def test_sun_at_a_baked_direction_picks_that_direction_only():
    t = make(specs=("hemi:8", "hemi:8", "hemi:8"))
    d = parse_directions("hemi:8")
    k = int(np.argmax(d.directions[:, 2]))
    w = ptt.light_weights(d, ptt.Sun(tuple(d.directions[k]), 0.0, 2.0))
    # the other weights are 0 up to rounding (3e-16 on some CPUs' SIMD paths)
    assert np.count_nonzero(np.abs(w[:, 0]) > 1e-12) == 1 and w[k, 0] == pytest.approx(2.0)
    E = t.irradiance(ptt.Sun(tuple(d.directions[k]), 0.0, 2.0), orders=(0,))
    np.testing.assert_allclose(E[:, 0], 2.0 * t.direct[k], rtol=1e-6)
    below = ptt.light_weights(d, ptt.Sun((0.0, 0.6, -0.8)))
    assert not below.any()


def test_environment_weights_are_radiance_times_solid_angle():
    d = parse_directions("hemi:8")
    env = np.ones((8, 16, 3)) * np.array([1.0, 2.0, 3.0])
    w = ptt.light_weights(d, ptt.Environment(env, "bottom_first", 0.0, 0.5))
    np.testing.assert_allclose(w, 0.5 * d.solid_angles[:, None] * [1.0, 2.0, 3.0])


def test_save_load_round_trip_and_refusals(tmp_path):
    t = make()
    path = str(tmp_path / "m.npz")
    t.save(path)
    u = ptt.TransferTensors.load(path)
    for name in ("direct", "one", "two", "receiver_region", "receiver_albedo", "base_colors"):
        np.testing.assert_array_equal(getattr(u, name), getattr(t, name))
    assert u.regions == t.regions and u.objects == t.objects and u.specs == t.specs
    assert u.metadata == {"note": "synthetic"} and u.bounces == 2
    assert u.object_slices() == {"a": slice(0, 30), "b": slice(30, 40)}
    with np.load(path) as z:
        header = json.loads(bytes(z["header"]).decode())
        arrays = {k: z[k] for k in z.files}
    header["version"] = 99
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    np.savez(str(tmp_path / "old.npz"), **arrays)
    with pytest.raises(ValueError, match="bake the materials again"):
        ptt.TransferTensors.load(str(tmp_path / "old.npz"))
    with pytest.raises(KeyError, match="not an editable region: Nope"):
        t.albedos({"Nope": (1, 1, 1)})
    with pytest.raises(ValueError, match="non-negative"):
        t.albedos({"M0": (1, -1, 1)})
    with pytest.raises(ValueError, match="one-bounce term has shape"):
        ptt.TransferTensors(t.direct, t.one[:, :, :2], t.two, t.specs, t.regions, t.base_colors,
                            t.receiver_region, t.receiver_albedo, t.objects)


def test_bake_count_matches_the_paper_formula_with_references():
    # S0 + S1 (R+1) + S2 ((R+1) + (R+1)^2): the two-bounce terms subtract a reference per r2
    assert ptt.bake_count(64, 16, 4, 3, 2) == 64 + 16 * 4 + 4 * (4 + 16)
    assert ptt.bake_count(64, 16, 4, 3, 1) == 64 + 16 * 4
    assert ptt.bake_count(64, 16, 4, 3, 0) == 64


def with_gloss(t, roughness=(0.2, 0.6), seed=3):
    """``t`` with random glossy-anchor terms (S1, R, K, V) and file finishes."""
    rng = np.random.default_rng(seed)
    R, V = len(t.regions), t.vertices
    gloss = rng.random((t.one.shape[0], R, len(roughness), V), dtype=np.float32)
    return dataclasses.replace(t, roughness=tuple(roughness), gloss=gloss,
                               base_finish=np.array([[0.0, 0.5]] * R))


def test_anchor_weights_interpolate_roughness_and_scale_by_metallic():
    w = ptt.anchor_weights((0.2, 0.6, 1.0), [1.0, 0.5, 1.0, 0.0], [0.4, 0.2, 2.0, 0.5])
    np.testing.assert_allclose(w, [[0.5, 0.5, 0], [0.5, 0, 0], [0, 0, 1], [0, 0, 0]])
    assert ptt.parse_anchors("diffuse") == ()
    assert ptt.parse_anchors("roughness:0.9,0.2") == (0.2, 0.9)
    for bad in ("roughness:", "roughness:0.2,0.2", "roughness:0.01", "rough:0.5",
                "roughness:0.1,0.2,0.3,0.4,0.5", "roughness:x", "roughness:nan,0.5"):
        with pytest.raises(ValueError):
            ptt.parse_anchors(bad)


@pytest.mark.parametrize("light", [ptt.Sun((0.3, -0.2, 0.9), 3.0, 2.5, (1.0, 0.5, 0.25)),
                                   ptt.Environment(np.random.default_rng(1).random((16, 32, 3)),
                                                   "bottom_first", 40.0, 0.7)])
def test_a_metallic_region_trades_its_diffuse_terms_for_its_glossy_anchors(light):
    t = with_gloss(make())
    w = [ptt.light_weights(d, light) for d in t.direction_sets()]
    edits = {"M0": (0.2, 0.4, 0.9), "M1": (0.7, 0.6, 0.5)}
    c = t.albedos(edits)
    # metallic 0: the anchors add nothing, the diffuse polynomial is unchanged
    np.testing.assert_allclose(t.irradiance(light, edits, finish={"M0": (0.0, 0.3)}),
                               brute_force(t, w, c), rtol=2e-5)
    # metallic 0.25 at roughness 0.3 (a quarter of the way from anchor 0.2 to 0.6), by loops
    m, k = 0.25, (0.75, 0.25)
    cd = c.copy()
    cd[1] *= 1 - m
    # without the composition the pairs a metal starts keep their diffuse light, and a second
    # surface reflects its whole colour
    expect = brute_force(t, w, c, c_one=cd)
    for ch in range(3):
        for s in range(t.one.shape[0]):
            for j in range(2):
                expect[:, ch] += c[1, ch] * m * k[j] * w[1][s, ch] * t.gloss[s, 0, j]
    got = t.irradiance(light, edits, finish={"M0": (m, 0.3)})
    np.testing.assert_allclose(got, expect, rtol=2e-5)
    # a metal receiver has no diffuse colour left: its shading scales by 1 - m
    col = t.receiver_colors(c, t.anchor_weights({"M0": (m, 0.3)}))
    np.testing.assert_allclose(col[t.receiver_region == 1], np.tile(cd[1], (np.sum(
        t.receiver_region == 1), 1)), rtol=1e-6)


def test_glossy_second_bounce_is_composed_through_the_transfer(tmp_path):
    from relightable_textures.lt_addon.transport import bounce_transfer as bt

    t = with_gloss(make(V=40))
    V, R1 = t.vertices, 3
    rng = np.random.default_rng(5)
    patch = rng.integers(0, 6, V).astype(np.int32)
    owner = np.repeat(np.arange(R1), 2).astype(np.int16)
    scale = np.array([[1.0, 2.0, 0.0], [1.5, 0.0, 0.0], [1.0, 3.0, 0.0]])
    t.bounce = bt.BounceTransfer(patch, owner, rng.random((6, V), dtype=np.float32),
                                 np.ones((V, 3), np.float32), scale)
    sun = ptt.Sun((0.2, 0.1, 0.97))
    p = t.project(sun)
    assert p.gloss_two.shape == (3, 2, 2, R1, V)
    # region 1's glossy light, reflected by the regions as the diffuse light of a source
    # with that region's calibration (1.5 into region 0; pair 1 -> 1 was blended: the
    # median of the pairs composed into region 1, 2.5)
    src = p.gloss[:, 0, 1][:, None]
    got = p.gloss_two[:, 0, 1]
    want = t.bounce.compose_sources(src, np.array([[1.5, 2.5, 0.0]]))[:, 0]
    np.testing.assert_allclose(got, want, rtol=1e-6)
    assert not np.any(p.gloss_two[:, :, :, 2])        # region 2 is never composed into
    # metal region 1: its glossy light's second bounce comes in, the diffuse pairs it starts
    # go where that is composed (into regions 0 and 1, not 2: they stay, as diffuse); as a
    # second surface it stays diffuse with its colour
    np.testing.assert_array_equal(p.gloss_covers, [[True, True, False], [True, True, False]])
    c = t.albedos({"M0": (0.9, 0.5, 0.2)})
    a = t.anchor_weights({"M0": (1.0, 0.6)})
    two = t.combine(p, c, (2,), a)
    want = np.zeros((V, 3))
    for ch in range(3):
        for r1 in range(R1):
            for r2 in range(R1):
                first = 0.0 if r1 == 1 and r2 != 2 else c[r1, ch]
                want[:, ch] += first * c[r2, ch] * p.two[ch, r1, r2]
            want[:, ch] += c[1, ch] * c[r1, ch] * p.gloss_two[ch, 0, 1, r1]
    np.testing.assert_allclose(two, want, rtol=1e-5)
    # files keep the anchors (version 3; without anchors a file stays version 2)
    t.save(str(tmp_path / "g.npz"))
    make().save(str(tmp_path / "d.npz"))
    for name, version in (("g", 3), ("d", 2)):
        with np.load(str(tmp_path / f"{name}.npz")) as z:
            assert json.loads(bytes(z["header"]).decode())["version"] == version
    back = ptt.TransferTensors.load(str(tmp_path / "g.npz"))
    assert back.roughness == (0.2, 0.6)
    np.testing.assert_array_equal(back.gloss, t.gloss)
    np.testing.assert_array_equal(back.irradiance(sun, finish={"M1": (0.5, 0.9)}),
                                  t.irradiance(sun, finish={"M1": (0.5, 0.9)}))


def test_a_metallic_edit_without_glossy_anchors_is_refused():
    t = make()
    with pytest.raises(ValueError, match="glossy anchors"):
        t.irradiance(ptt.Sun((0, 0, 1.0)), finish={"M0": (0.5, 0.5)})
    # metallic 0 is the diffuse bake itself
    np.testing.assert_array_equal(t.irradiance(ptt.Sun((0, 0, 1.0)), finish={"M0": (0, 0.5)}),
                                  t.irradiance(ptt.Sun((0, 0, 1.0))))


def test_gathered_files_round_trip_the_receiver_transfer_half_floats_and_the_gloss_set(tmp_path):
    """A bake with gathered bounces: the receiver transfer (a sun's exact one-bounce light) and
    glossy anchors at their own direction set (version 4) survive the file; the transfer adds
    exactly its product to the blended one-bounce light."""
    from scipy import sparse

    from relightable_textures.lt_addon.transport.gathered_transfer import ReceiverTransfer

    t = with_gloss(make(V=40))
    V, R1, S1 = t.vertices, 3, t.one.shape[0]
    rng = np.random.default_rng(8)
    g = parse_directions("hemi:6")
    t = dataclasses.replace(t, gloss_spec=g.spec,
                            gloss=rng.random((g.size, 2, 2, V), dtype=np.float32))
    mats = [sparse.random(V, V, density=0.2, random_state=r, format="csc", dtype=np.float32)
            for r in range(R1)]
    t.receiver_transfer = ReceiverTransfer(sparse.vstack(mats).tocsc(),
                                           rng.random((S1, V)).astype(np.float16),
                                           np.ones((V, 3), np.float32))
    path = str(tmp_path / "r.npz")
    t.save(path)
    with np.load(path) as z:
        assert json.loads(bytes(z["header"]).decode())["version"] == 4
    u = ptt.TransferTensors.load(path)
    assert u.gloss_spec == "hemi:6"
    np.testing.assert_array_equal(u.gloss, t.gloss)
    assert (u.receiver_transfer.matrix != t.receiver_transfer.matrix).nnz == 0
    sun = ptt.Sun((0.3, 0.2, 0.93), 0.0, 2.0, (1.0, 0.8, 0.5))
    exact = rng.random(V).astype(np.float32)
    p = u.project(sun, direct=exact)
    plain = dataclasses.replace(u, receiver_transfer=None)
    bare = plain.project(sun, direct=exact)
    idx, k = ptt.sun_weights(u.direction_sets()[1], sun.direction)
    d = exact - k.astype(np.float32) @ u.receiver_transfer.direct_one[idx].astype(np.float32)
    d[np.abs(d) <= 1e-2] = 0.0
    rgb = 2.0 * np.array([1.0, 0.8, 0.5], np.float32)
    for r in range(R1):
        want = rgb[:, None] * (mats[r].toarray() @ d)[None, :]
        np.testing.assert_allclose(p.one[:, r] - bare.one[:, r], want, rtol=1e-4, atol=1e-5)
    assert p.fixed == int(np.sum(d != 0)) > 0
    # an environment has no exact direct term: nothing is corrected
    env = ptt.Environment(rng.random((8, 16, 3)), "bottom_first")
    np.testing.assert_array_equal(u.project(env).one, plain.project(env).one)
    assert u.project(env).fixed == 0
