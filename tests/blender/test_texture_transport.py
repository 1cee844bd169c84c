"""Direction-sampled transport textures with real Cycles at tiny sizes (fixed seeds).

Independent references: fresh Cycles bakes of the same sun / environment / steerable light, a
Cycles render of the preview node group, and the scene's own objects baked one at a time.
"""

import json
import os

import numpy as np
import pytest
from render_check import render_rgb

from relightable_textures import samples
from relightable_textures.lt_addon.transport import gathered_texture as gt
from relightable_textures.lt_addon.transport import texture as tt
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el

R = 16


def rel(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.fixture
def bumps(fresh_scene):
    import bpy

    samples.build("bumps", fresh_scene, "test")
    return fresh_scene, bpy.data.objects["Bumps"]


@pytest.fixture
def statue(fresh_scene):
    import bpy

    samples.build("statue", fresh_scene, "test")
    return fresh_scene, bpy.data.objects["Statue"], bpy.data.objects["Ground"]


#: Directions of :func:`settings`' set: hemi:48:1.5 and the 9 of its band under 5 degrees,
#: mirrored under the horizon (lt_addon/sphere/under_horizon.py), the set's first rows.
S, UNDER = 57, 9


def settings(**kw):
    from relightable_textures.operators.bakes.texture_transport import TransportTextureSettings

    base = dict(directions="hemi:48:1.5", resolution=R, bounces=0, model="pca", components=48,
                table_size=16)
    base.update(kw)
    return TransportTextureSettings(**base)


def bake(scene, objects, out, resume=True, **kw):
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    return run(tx.bake_transport_textures(scene, objects, settings(**kw), str(out), resume))


def sun_bake(scene, objects, direction, angle=0.0, spp=1, bounces=0, passes="direct",
             mode="irradiance", seed=0, res=R):
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    with EnvironmentBake(scene, objects, res, spp, bounces, (8, 16), mode=mode, seed=seed,
                         world_sampling="none", passes=passes) as s:
        return s.bake_sun_all(direction, 1.0, angle)


def test_relight_at_a_sample_direction_with_a_point_sun_equals_that_directions_bake(bumps,
                                                                                     tmp_path):
    """The linear kernel is exact at a baked direction (0-degree sun); the store keeps half
    floats, so the bake agrees to half precision (2^-11 relative). T from Cycles calls: the
    reference is Cycles' bake (rays against it: test_ray_direct.py)."""
    scene, obj = bumps
    res = bake(scene, [obj], tmp_path, model="none", direct="cycles")
    store = tt.TransportStore.open(res.objects[0].store_path)
    assert store.directions.size == S and (store.directions.directions[:UNDER, 2] < 0).all()
    for s in (UNDER, UNDER + 20, S - 1):           # (a sun under the horizon is off)
        d = store.directions.directions[s]
        fresh = sun_bake(scene, [obj], d)[0][..., 0]
        relit = store.sun(d, 0.0, "linear")
        assert fresh.max() > 0.05
        assert np.abs(relit - fresh).max() <= 2.0 ** -11 * fresh.max() + 1e-7


@pytest.mark.parametrize("direct,steps", [("cycles", 10), ("rays", 2)])
def test_stores_are_streamed_and_cancel_leaves_nothing(bumps, tmp_path, direct, steps):
    from relightable_textures.operators.bakes import texture_transport as tx

    scene, obj = bumps
    # rays: the albedo, then the first chunk of directions (all 57 here) is in the store
    gen = tx.bake_transport_textures(scene, [obj], settings(direct=direct), str(tmp_path))
    for _ in range(steps):
        next(gen)
    partial = [p for p in os.listdir(tmp_path) if p.endswith(".npy")]
    assert partial and all(p.startswith(".") for p in partial)   # temporary name while baking
    gen.close()
    assert os.listdir(tmp_path) == []
    assert not any(o.name.startswith("RelightBake") for o in scene.objects)


def test_a_cancelled_bake_resumes_from_its_finished_chunks_bit_for_bit(bumps, tmp_path):
    """Issue 15's chunk cache: a bake cancelled after 2 of its 3 chunks of 16 directions keeps
    those chunks (and nothing else); the rerun reuses them and its T equals an uninterrupted
    bake's bit for bit (1 spp, fixed seed: Cycles is deterministic here); writing the bake
    removes the cache; moving an object invalidates it (nothing reused, the stale folder
    pruned)."""
    from relightable_textures.operators.bakes import texture_transport as tx

    scene, obj = bumps
    # the chunk cache keeps Cycles calls' directions (rays need none: a rerun casts them again)
    ref = bake(scene, [obj], tmp_path / "ref", resume=False, model="none", direct="cycles")
    assert ref.chunks == {} or ref.chunks["chunks_reused"] == 0
    T_ref = np.load(ref.objects[0].store_path)
    out = tmp_path / "out"

    def cancel_after(directions):
        gen = tx.bake_transport_textures(scene, [obj], settings(model="none", direct="cycles"),
                                         str(out))
        for _ in range(1 + directions):            # the albedo, then the directions
            next(gen)
        gen.close()

    cancel_after(40)
    assert os.listdir(out) == [tx.CACHE_FOLDER]     # no store, no report: only the chunks
    (folder,) = list((out / tx.CACHE_FOLDER / "Bumps").iterdir())
    assert sorted(p.name for p in folder.iterdir()) == [
        "direct_00000.npy", "direct_00000.npy.sha256", "direct_00016.npy",
        "direct_00016.npy.sha256", "key.json"]
    res = bake(scene, [obj], out, model="none", direct="cycles")
    assert res.chunks == {"chunks_total": 4, "chunks_reused": 2, "chunk_directions": 16,
                          "direct_chunks": 4, "indirect_chunks": 0, "chunks_rejected": 0}
    np.testing.assert_array_equal(np.load(res.objects[0].store_path), T_ref)
    reports = tx.write_bake(res, [obj], str(out))
    assert reports[0]["chunks_reused"] == 2 and tx.CACHE_FOLDER not in os.listdir(out)

    # issue 34: a kept chunk whose values are NaN (a faulty worker or disk: a valid .npy) is
    # refused on reuse and baked again; the result is still the uninterrupted bake's, bit for bit
    cancel_after(40)
    (folder,) = list((out / tx.CACHE_FOLDER / "Bumps").iterdir())
    kept = np.load(folder / "direct_00016.npy")
    np.save(folder / "direct_00016.npy", np.full_like(kept, np.nan))
    res = bake(scene, [obj], out, model="none", direct="cycles")
    assert (res.chunks["chunks_reused"], res.chunks["chunks_rejected"]) == (1, 1)
    np.testing.assert_array_equal(np.load(res.objects[0].store_path), T_ref)
    tx.write_bake(res, [obj], str(out))

    cancel_after(20)
    obj.location.x += 0.01                          # the scene changed: no chunk may be reused
    res = bake(scene, [obj], out, model="none", direct="cycles")
    assert res.chunks["chunks_reused"] == 0
    assert len(list((out / tx.CACHE_FOLDER / "Bumps").iterdir())) == 1   # the stale one pruned
    obj.location.x -= 0.01


def test_the_cache_key_follows_shading_not_layout(bumps):
    """What invalidates the chunks: geometry, transforms, material values and links; what does
    not: a node moved in the editor, our own preview nodes."""
    from relightable_textures.lt_addon.io.chunk_cache import digest
    from relightable_textures.operators.base.bake_inputs import scene_key

    scene, obj = bumps
    key = lambda: digest(scene_key(scene, [obj]))
    k0 = key()
    tree = obj.active_material.node_tree
    bsdf = next(n for n in tree.nodes if "Roughness" in n.inputs)   # the diffuse BSDF
    bsdf.location.x += 300.0
    assert key() == k0
    preview = tree.nodes.new("ShaderNodeEmission")
    preview["relight_preview"] = True
    assert key() == k0
    tree.nodes.remove(preview)
    old = bsdf.inputs["Roughness"].default_value
    bsdf.inputs["Roughness"].default_value = old + 0.1
    assert key() != k0
    bsdf.inputs["Roughness"].default_value = old
    assert key() == k0
    obj.data.vertices[0].co.z += 1e-3
    obj.data.update()
    assert key() != k0


def test_quadrature_steerable_light_equals_its_environment_bake(bumps, tmp_path):
    """Sampled steerable light k by quadrature over 600 hard suns vs Cycles baking the same
    light as an environment (direct light): agreement to the environment bake's own noise."""
    from relightable_textures.lt_addon.steerable.sampled_basis import build_sampled_basis
    from relightable_textures.lt_addon.steerable.basis import paper_basis
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    scene, obj = bumps
    res = bake(scene, [obj], tmp_path, directions="hemi:600:1.0", model="none")
    store = tt.TransportStore.open(res.objects[0].store_path)
    sampled = build_sampled_basis(paper_basis(3))
    quad = tt.quadrature_sampled_lights(store, sampled)
    h = 128
    k = 4   # the central light
    env = sampled.light_environment(k, h, 2 * h, row_order="bottom_first")
    baked = []
    for seed in (1, 2):
        with EnvironmentBake(scene, obj, R, 256, 0, (h, 2 * h), mode="irradiance", seed=seed,
                             world_sampling="importance", passes="direct") as s:
            baked.append(s.bake(env)[..., 0])
    noise = rel(baked[0], baked[1]) / np.sqrt(2)     # one bake's relative noise
    err = rel(quad[k], 0.5 * (baked[0] + baked[1]))
    # T samples each texel at its centre (Cycles' first bake sample), the 256-spp bake averages
    # the texel: measure that aliasing term on one hard sun of this scene (~3 % at 16^2)
    d = direction_from_az_el(30.0, 45.0)
    alias = rel(sun_bake(scene, [obj], d)[0], sun_bake(scene, [obj], d, spp=256)[0])
    # 3 sigma of the two-bake mean's noise, the aliasing term and 0.5 % quadrature error
    assert err <= 3 * noise / np.sqrt(2) + alias + 0.005, (err, noise, alias)


def test_pca_model_is_exact_at_full_rank_and_viewport_twin_matches(bumps, tmp_path):
    from relightable_textures.operators.preview import transport_preview as tp

    scene, obj = bumps
    res = bake(scene, [obj], tmp_path, components=S)
    b = res.objects[0]
    store = tt.TransportStore.open(b.store_path)
    for az, el in ((30, 20), (200, 65)):
        idx, w = tt.sun_weights(store.directions, direction_from_az_el(az, el), 3.0)
        full = store.relight(idx, w)
        assert rel(b.model.relight(idx, w), full) < 1e-5
    # tables sampled at a texel centre equal the kernel weights applied to the loadings
    eig, tab = tp.preview_arrays(b.model, b.albedo, store.directions, 3.0, 16)
    from relightable_textures.lt_addon.sphere.hemisphere import disk_to_hemisphere

    d = disk_to_hemisphere(tt.disk_grid(16)[9, 6][None])[0]
    idx, w = tt.sun_weights(store.directions, d, 3.0)
    want = store.relight(idx, w)[..., None] * b.albedo
    assert rel(tp.viewport_relight(eig, tab, d), want) < 1e-5


@pytest.mark.version_sensitive
def test_preview_group_rendered_by_cycles_equals_numpy_twin(bumps, tmp_path):
    """The node group (disk point, table and eigen atlases, albedo tile, half floats) rendered by
    Cycles through the top camera equals viewport_relight of the half-float atlases."""
    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.lt_addon.io.atlas import unpack_atlas
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.preview import transport_preview as tp
    from relightable_textures.operators.base.jobs import run

    scene, obj = bumps
    s = settings(components=12, sun_angle=4.0, viewport="pca")
    reports = run(tx.bake_job(scene, [obj], s, str(tmp_path), truth=0)).reports
    prev = reports[0]["preview"]
    ntile = prev["tiles"]
    eig = unpack_atlas(np.stack([exrio.read_exr(prev["eigen"])[0][c] for c in "RGB"], -1),
                       ntile + 1, R)
    tab = unpack_atlas(np.stack([exrio.read_exr(prev["tables"])[0][c] for c in "RGB"], -1),
                       ntile, 16)
    for az, el, inten in ((40.0, 35.0, 2.0), (250.0, 12.0, 1.0)):
        scene["relight_azimuth"], scene["relight_elevation"] = az, el
        scene["relight_intensity"] = inten
        img = render_rgb(scene, tmp_path, R)
        want = inten * tp.viewport_relight(eig, tab, direction_from_az_el(az, el))
        assert want.max() > 0.05
        assert np.abs(img - want).max() <= 2.0 ** -10 * want.max()
    scene["relight_elevation"] = -20.0         # below the horizon: off
    assert np.abs(render_rgb(scene, tmp_path, R)).max() == 0.0


def _sparse_preview(prev, resolution=R):
    """(8-bit tiles (n, R, R, 3) as in the PNG atlas, indices, scaled weights, albedo tile of
    the half-float eigen atlas) -- what the sparse group reads."""
    import json

    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.lt_addon.io.atlas import unpack_atlas
    from relightable_textures.lt_addon.io.contact_sheet import read_png
    from relightable_textures.operators.preview import transport_preview as tp

    def rgb(path):
        ch = exrio.read_exr(path)[0]
        return np.stack([ch[c] for c in "RGB"], -1)

    with open(prev["transport_scales"]) as fh:
        n = json.load(fh)["tiles"]
    tiles = unpack_atlas(read_png(prev["transport_atlas"])[::-1], n, resolution)
    albedo = unpack_atlas(rgb(prev["eigen"]), prev["tiles"] + 1, resolution)[-1]
    return (tiles, tp.tables_from_parts(rgb(prev["sparse_index"])).astype(np.int64),
            tp.tables_from_parts(rgb(prev["sparse_weights"])), albedo)


@pytest.mark.version_sensitive
def test_transport_viewport_rendered_by_cycles_equals_its_twin_and_T(bumps, tmp_path):
    """The viewport that relights from T itself: Cycles renders the sparse group (Closest
    index / weight tables at four disk texels, computed atlas tiles and channels, half-float
    atlas) equal to its NumPy twin to half precision; at a table texel centre the twin is the
    kernel's own relight of T (0-degree sun: the three barycentric directions), and elsewhere
    within the bilinear table error of it."""
    from relightable_textures.lt_addon.transport import sparse_tables as sp
    from relightable_textures.lt_addon.sphere.hemisphere import disk_to_hemisphere
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.preview import transport_preview as tp
    from relightable_textures.operators.base.jobs import run

    scene, obj = bumps
    s = settings(sun_angle=0.0, viewport="transport")
    rep = run(tx.bake_job(scene, [obj], s, str(tmp_path), truth=0)).reports[0]
    prev = rep["preview"]
    assert prev["viewport"] == "transport" and rep["preview_cost"]["viewport"] == "transport"
    assert rep["model_vs_T"]["viewport"] == "transport"
    tiles, idx, wts, albedo = _sparse_preview(prev)
    assert idx.shape == (64, 64, 3) and tiles.shape[0] == S // 3 and tiles.dtype == np.uint8
    store = tt.TransportStore.open(rep["files"]["transport"])
    albedo = albedo.astype(np.float64)
    # at a table texel centre: exactly T's kernel relight up to the 8-bit atlas (half a step
    # of each direction's own maximum, 1/510 of it at most per texel: 2e-3 relative)
    d = disk_to_hemisphere(tt.disk_grid(64)[40, 21][None])[0]
    want = store.sun(d, 0.0)[..., None] * albedo
    assert rel(tp.viewport_relight_sparse(tiles, idx, wts, albedo, d), want) < 2e-3
    for az, el, inten in ((40.0, 35.0, 2.0), (250.0, 12.0, 1.0)):
        scene["relight_azimuth"], scene["relight_elevation"] = az, el
        scene["relight_intensity"] = inten
        img = render_rgb(scene, tmp_path, R)
        d = direction_from_az_el(az, el)
        twin = inten * tp.viewport_relight_sparse(tiles, idx, wts, albedo, d)
        assert twin.max() > 0.05
        assert np.abs(img - twin).max() <= 2.0 ** -10 * twin.max()
        # and the twin is T's relight within the 64^2 tables' bilinear error
        full = inten * store.sun(d, 0.0)[..., None] * albedo
        assert rel(twin, full) < 0.05, rel(twin, full)
    scene["relight_elevation"] = -20.0         # below the horizon: off
    assert np.abs(render_rgb(scene, tmp_path, R)).max() == 0.0
    # a 25-degree sun (the Sun Size slider re-tabulates in place): three taps per table texel
    # no longer hold 85 % of its kernel, so the group is rebuilt with more (the tables' further
    # parts), and the render still equals the twin
    import bpy

    bake_, store_, report_ = tx.load_bake(rep["report"])
    tp.rewrite_tables(obj, report_, bake_, store_, 25.0)
    _, idx25, wts25, _ = _sparse_preview(prev)
    assert idx25.shape[-1] > 3 and np.count_nonzero(wts25[..., 3:]) > 1000
    group = bpy.data.node_groups[prev["group"]]
    assert group["relight_taps"] == idx25.shape[-1]
    assert len([n for n in group.nodes if n.bl_idname == "ShaderNodeTexImage"]) == \
        4 * (2 * idx25.shape[-1] // 3 + idx25.shape[-1]) + 1
    scene["relight_azimuth"], scene["relight_elevation"] = 130.0, 20.0
    scene["relight_intensity"] = 1.0
    img = render_rgb(scene, tmp_path, R)
    twin = tp.viewport_relight_sparse(tiles, idx25, wts25, albedo, direction_from_az_el(130, 20))
    assert np.abs(img - twin).max() <= 2.0 ** -10 * twin.max()
    # each table texel keeps its kernel's own mass (1 inside the baked directions' hull, less
    # towards the horizon, where the linear kernel fades the light out); indices are directions
    scales = np.asarray(json.load(open(prev["transport_scales"]))["scales"])
    sums = np.where(wts != 0, wts / scales[idx], 0.0).sum(-1)
    for i, j in ((32, 32), (40, 21), (3, 30), (60, 50)):
        _, w = tt.sun_weights(store.directions, disk_to_hemisphere(
            tt.disk_grid(64)[i, j][None] * min(1.0, 0.999 / np.hypot(*tt.disk_grid(64)[i, j]))
        )[0], 0.0)
        assert abs(sums[i, j] - w.sum()) < 1e-5
    assert sums.max() <= 1.0 + 1e-5 and idx.max() < S
    # the scales are the directions' maxima: every direction's brightest texel reads 255
    T = np.asarray(store.array, np.float64)
    assert np.allclose(scales, np.where(T.max(1) > 0, T.max(1), 1.0), rtol=1e-12)
    assert sp.choose_viewport("auto", 48, R)[0] == "transport"


@pytest.mark.version_sensitive
def test_block_viewport_rendered_by_cycles_equals_its_twin_and_T(bumps, tmp_path):
    """The block viewport (a PCA per 8 x 8 texel block, its cell and table lookups computed in
    the tree from the UV): Cycles renders the group equal to its NumPy twin to half precision;
    at full rank per block the twin is T's own relight within the bilinear table error, and a
    new sun size re-tabulates it in place."""
    import bpy

    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.lt_addon.io.atlas import unpack_atlas
    from relightable_textures.lt_addon.transport import block_viewport as bv
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.preview import transport_preview as tp
    from relightable_textures.operators.base.jobs import run

    scene, obj = bumps
    # a budget no block viewport fits is refused with its figure before any bake call (nothing
    # is made, not even the folder)
    with pytest.raises(tx.BakeInputError, match="does not fit 8 MiB of GPU memory at 4096"):
        run(tx.bake_job(scene, [obj], settings(resolution=4096, viewport="blocks",
                                               gpu_budget=8), str(tmp_path / "no"), truth=0))
    assert not (tmp_path / "no").exists()
    s = settings(sun_angle=0.0, viewport="blocks", table_size=16)
    rep = run(tx.bake_job(scene, [obj], s, str(tmp_path), truth=0)).reports[0]
    prev, info = rep["preview"], rep["viewport"]
    assert prev["viewport"] == "blocks" and rep["preview_cost"]["viewport"] == "blocks"
    assert info["shows"] == "blocks" and info["block"] == 8 and prev["block"] == 8
    assert rep["model_vs_T"]["viewport"] == "blocks"
    k = info["components"]
    assert k == 24 and rep["preview_cost"]["texture_lookups_per_pixel"] == bv.lookups_per_pixel(k)
    view = bv.load(rep["files"]["viewport_blocks"], tt.TransportStore.open(rep["files"]["transport"]))
    assert view.k == k and view.block == 8

    def rgb(path):
        ch = exrio.read_exr(path)[0]
        return np.stack([ch[c] for c in "RGB"], -1)

    n = -(-k // 3)
    Rp = 2 * (8 + 2)
    eig = unpack_atlas(rgb(prev["block_eigen"]), n + 1, Rp)
    tab = unpack_atlas(rgb(prev["block_tables"]), n, 2 * 16)
    store = tt.TransportStore.open(rep["files"]["transport"])
    for az, el, inten in ((40.0, 35.0, 2.0), (250.0, 12.0, 1.0)):
        scene["relight_azimuth"], scene["relight_elevation"] = az, el
        scene["relight_intensity"] = inten
        img = render_rgb(scene, tmp_path, R)
        d = direction_from_az_el(az, el)
        twin = inten * tp.viewport_relight_blocks(eig, tab, d, 8, R, 16)
        assert twin.max() > 0.05
        assert np.abs(img - twin).max() <= 2.0 ** -10 * twin.max()
        # 24 components of 64-texel blocks: T's relight up to the 16^2 tables' bilinear error
        full = inten * store.sun(d, 0.0)[..., None] * eig[n][np.arange(Rp) % 10 % 9 != 0][
            :, np.arange(Rp) % 10 % 9 != 0]
        assert rel(twin, full) < 0.1, rel(twin, full)
    scene["relight_elevation"] = -20.0         # below the horizon: off
    assert np.abs(render_rgb(scene, tmp_path, R)).max() == 0.0
    # a new sun size rewrites the block tables in place; the render follows
    bake_, store_, report_ = tx.load_bake(rep["report"])
    assert bake_.view is not None
    tp.rewrite_tables(obj, report_, bake_, store_, 10.0)
    tab10 = unpack_atlas(rgb(prev["block_tables"]), n, 2 * 16)
    assert np.abs(tab10 - tab).max() > 1e-3
    scene["relight_azimuth"], scene["relight_elevation"] = 130.0, 20.0
    scene["relight_intensity"] = 1.0
    img = render_rgb(scene, tmp_path, R)
    twin = tp.viewport_relight_blocks(eig, tab10, direction_from_az_el(130, 20), 8, R, 16)
    assert np.abs(img - twin).max() <= 2.0 ** -10 * twin.max()
    assert bpy.data.node_groups[prev["group"]]["relight_viewport"] == "blocks"


def test_two_objects_baked_together_shadow_each_other(statue, tmp_path):
    """Statue and ground in the same Cycles calls: each texture equals that object baked alone
    (exactly: same seed, 1 spp), and the ground shows the statue's shadow (darker than the
    ground baked with the statue hidden)."""
    scene, statue_obj, ground = statue
    res = bake(scene, [statue_obj, ground], tmp_path, directions="hemi:24", model="none",
               texel_sampling="centre")      # (1 spp: the texel centres)
    assert [b.name for b in res.objects] == ["Statue", "Ground"]
    stores = [tt.TransportStore.open(b.store_path) for b in res.objects]
    d = stores[1].directions.directions[3]
    # the texels the bakes sample (Blender 5.3's bake margin is not the Extend margin the ray
    # bake reproduces: test_ray_direct.py)
    from relightable_textures.lt_addon.rays.texels import texel_samples
    from relightable_textures.operators.base.meshes import uv_triangles

    def covered(o):
        m = np.zeros(R * R, bool)
        m[texel_samples(uv_triangles(o), R).texel] = True
        return m.reshape(R, R)

    alone = sun_bake(scene, [ground], d)[0][..., 0]
    m = covered(ground)
    np.testing.assert_allclose(stores[1].sun(d)[m], alone[m], atol=2.0 ** -11 * alone.max())
    alone_statue = sun_bake(scene, [statue_obj], d)[0][..., 0]
    m = covered(statue_obj)
    np.testing.assert_allclose(stores[0].sun(d)[m], alone_statue[m],
                               atol=2.0 ** -11 * alone_statue.max())
    statue_obj.hide_render = True
    unshadowed = sun_bake(scene, [ground], d)[0][..., 0]
    statue_obj.hide_render = False
    shadow = unshadowed - stores[1].sun(d)
    assert shadow.max() > 0.5 * unshadowed.max()      # some ground texels lose most light
    assert shadow.min() >= -1e-3


def test_environment_relight_equals_a_cycles_bake_of_the_same_hdri(bumps, tmp_path):
    """A smooth sky (upper hemisphere) relit from T vs Cycles baking it (direct light)."""
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    scene, obj = bumps
    res = bake(scene, [obj], tmp_path, directions="hemi:600:1.0", model="none")
    b = res.objects[0]
    store = tt.TransportStore.open(b.store_path)
    h = 64
    v = (np.arange(h) + 0.5) / h                      # bottom first
    u = (np.arange(2 * h) + 0.5) / (2 * h)
    el = (v - 0.5) * np.pi
    sky = np.where(el[:, None] > 0, 1.0 + 0.8 * np.cos(2 * np.pi * u)[None, :] * np.cos(el)[:, None],
                   0.0)
    env = np.stack([sky, 0.8 * sky, 0.6 * sky], -1).astype(np.float32)
    for rot in (0.0, 70.0):
        relit = tx.relight_environment(b, store, env, rot, row_order="bottom_first")
        if rot:
            # rotating the environment by +rot about z = sampling it at azimuth - rot
            shift = int(round(rot / 360.0 * 2 * h))
            env_r = np.roll(env, -shift, axis=1)
        else:
            env_r = env
        baked = []
        for seed in (1, 2):
            with EnvironmentBake(scene, obj, R, 256, 0, (h, 2 * h), mode="radiance", seed=seed,
                                 world_sampling="importance", passes="direct") as s:
                baked.append(s.bake(env_r))
        noise = rel(baked[0], baked[1]) / np.sqrt(2)
        err = rel(relit, 0.5 * (baked[0] + baked[1]))
        # centre-sampled T vs the area-averaged bake, as in the quadrature test
        d = direction_from_az_el(30.0, 45.0)
        alias = rel(sun_bake(scene, [obj], d)[0], sun_bake(scene, [obj], d, spp=256)[0])
        assert err <= 3 * noise / np.sqrt(2) + alias + 0.005, (rot, err, noise, alias)


def test_memory_is_refused_up_front_with_the_figure(bumps, tmp_path):
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.cycles_bake import BakeInputError

    scene, obj = bumps
    before = {o.name for o in scene.objects}
    with pytest.raises(BakeInputError, match=r"MiB"):
        next(tx.bake_transport_textures(scene, [obj],
                                        settings(directions="hemi:60000", resolution=8192),
                                        str(tmp_path)))
    assert {o.name for o in scene.objects} == before
    assert not os.listdir(tmp_path)


@pytest.mark.version_sensitive
def test_streaming_keeps_peak_memory_below_the_transport_size(bumps, tmp_path):
    """T (S x R^2 half floats) is never held: after the first direction (when Cycles has
    allocated its session), the anonymous resident memory (RssAnon; the store's memmap pages
    are page cache) grows by far less than T's size on disk while the other directions stream
    (here T = 400 x 160^2 x 2 bytes = 19.5 MiB; measured growth about 3 MiB on Blender 5.0.1
    and 5.7 MiB on 5.2.3, whose Cycles keeps more per bake). Holding T would grow by at least its
    size (twice that as float32), so half of it separates the two with room for Cycles' own
    growth. The fit's own bounded working set is tested in tests/core/test_transport_texture.py."""
    scene, obj = bumps
    res = bake(scene, [obj], tmp_path, directions="hemi:400", resolution=160, model="none")
    size_mb = os.path.getsize(res.objects[0].store_path) / 2 ** 20
    assert size_mb > 19
    assert res.growth_after_first_mb < 0.5 * size_mb, (res.growth_after_first_mb, size_mb)


def test_the_bake_is_refused_before_any_bake_call_when_its_stated_peak_memory_would_not_fit(
        bumps, tmp_path, monkeypatch):
    """The stated peak (lt_addon/transport/bake_memory.py: the largest stage, here the PCA's
    96 eigen-textures at 1024^2 and their half-float copy) against 80 % of the memory available:
    refused with that figure and the stage, before any bake call and any file; one byte more of
    memory and the check passes."""
    from relightable_textures.operators.bakes import bake_cost as be
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base import cycles_bake as cb

    scene, obj = bumps
    s = settings(resolution=1024, components=None, tol=0.03, viewport="auto")
    dset = s.validate()
    need, stage = be.memory_bytes(s, dset, 1)
    assert stage == "write" and need > 96 * 4 * 1024 ** 2
    calls = []
    monkeypatch.setattr(cb.EnvironmentBake, "__enter__", lambda self: calls.append(1))
    monkeypatch.setattr(cb, "available_memory_bytes", lambda: need / 0.8 - 1)
    with pytest.raises(tx.BakeInputError) as err:
        next(tx.bake_transport_textures(scene, [obj], s, str(tmp_path)))
    assert str(err.value).startswith(f"the bake of 1 object(s) at 1024^2 texels (write stage) "
                                     f"needs {cb._size(need)} but only ")
    assert not calls and not os.listdir(tmp_path)
    monkeypatch.setattr(cb, "available_memory_bytes", lambda: need / 0.8 + 1)
    tx.check_space(1, dset, s, str(tmp_path))


def test_cli_bake_textures_default_method_relight_and_force(tmp_path):
    from relightable_textures.operators import cli

    blend = str(tmp_path / "b.blend")
    assert cli.run(["scene", "bumps", "--out", blend]) == 0
    args = ["bake-textures", blend, "--object", "Bumps", "--preset", "draft", "--directions",
            "hemi:32", "--resolution", "16", "--indirect-resolution", "8",
            "--indirect-samples", "4", "--truth", "1", "--truth-samples", "8", "--bounces", "1"]
    assert cli.run(args) == 0
    rep_path = tmp_path / "b_relight" / "Bumps_texture_report.json"
    rep = json.loads(rep_path.read_text())
    assert rep["method"] == "transport" and rep["directions"] == 32 + 3   # 3 under the horizon
    assert rep["timings"]["wall_total"] >= rep["timings"]["bake_total"] > 0
    assert 0 < rep["ground_truth"]["headline_rel_rmse"] < 1
    assert rep["model"]["kind"] == "pca"
    stamp = rep_path.stat().st_mtime_ns
    assert cli.run(args) == 2                               # exists: refused without --force
    assert rep_path.stat().st_mtime_ns == stamp
    assert cli.run(args + ["--force"]) == 0
    out = str(tmp_path / "relit.exr")
    assert cli.run(["relight", blend, "--object", "Bumps", "--light", "30,20",
                    "--sun-angle", "5", "--out", out]) == 0
    assert os.path.getsize(out) > 0
    # compare: preview | Cycles Sun | difference, from the scene camera, each panel captioned
    from matplotlib.image import imread

    from relightable_textures.lt_addon.io.label import GLYPH_H

    png = tmp_path / "cmp.png"
    assert cli.run(["compare", blend, "--light", "30,20", "--sun-angle", "2", "--samples", "4",
                    "--resolution", "48", "--out", str(png)]) == 0
    img = imread(str(png))[..., :3]
    band = (GLYPH_H + 4) * 2
    assert img.shape == (48 + band, 3 * 48 + 2 * 4, 3)
    for col in range(3):                                      # white text on each dark band
        x0 = col * (48 + 4)
        caption = img[:band, x0:x0 + 48]
        assert np.any(np.all(caption > 0.99, axis=2)) and np.median(caption) < 0.2
    assert cli.run(["compare", blend, "--light", "30,20", "--out", str(png)]) == 2   # exists
    # lobes-only options are refused for the transport method, and vice versa
    assert cli.run(args + ["--order", "3"]) == 2
    assert cli.run(["bake-textures", blend, "--object", "Bumps", "--method", "lobes",
                    "--directions", "hemi:32"]) == 2


def test_panel_operator_bakes_selected_objects_and_sun_size_retabulates(statue, tmp_path):
    """The Relight tab's Bake (method transport, the default) through bpy.ops: the active and
    the other selected mesh are baked together, files and bake records written, the preview
    installed; the Sun Size slider rewrites the preview tables without a re-bake."""
    import bpy

    import relightable_textures
    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.operators.base.blend_files import object_bakes

    scene, statue_obj, ground = statue
    relightable_textures.register()
    try:
        props = scene.relight
        assert props.method == "transport"
        props.preset = "draft"
        props.directions, props.resolution, props.indirect_samples = 24, 16, 4
        props.truth_lights = 1
        props.output_dir = str(tmp_path) + os.sep
        props.device = "cpu"   # the panel's Device (default Auto); tests bake on the CPU
        for o in scene.objects:
            o.select_set(o in (statue_obj, ground))
        bpy.context.view_layer.objects.active = statue_obj
        engine, filepath = scene.render.engine, scene.render.filepath
        assert bpy.ops.relight.bake_textures() == {"FINISHED"}
        files = sorted(os.listdir(tmp_path))
        for name in ("Statue", "Ground"):
            assert f"{name}_texture_report.json" in files
            assert f"{name}_transport_texture.npy" in files
            assert f"{name}_preview_tables.exr" in files
        rep = json.loads((tmp_path / "Ground_texture_report.json").read_text())
        assert rep["objects_baked_together"] == ["Statue", "Ground"]
        # the device it baked on: in the report and in the panel (Baked On)
        assert rep["device"]["device"] == "CPU" and rep["device"]["choice"] == "cpu"
        assert props.device_used.startswith("CPU") and scene.cycles.device == "CPU"
        assert rep["directions"] == 24 + 5 and "ground_truth" in rep     # 5 under the horizon
        # the report's picture: preview | Cycles Sun | difference from the scene camera at the
        # held-out light, captioned, its cost in the report and its line in the panel
        cmp = rep["comparison"]
        assert cmp["png"] == str(tmp_path / "Statue_compare.png") and "Statue_compare.png" in files
        assert cmp["elevation"] == 10.0 and 0 < cmp["rel_rmse_covered_pixels"] < 1
        assert rep["timings"]["wall_total"] >= rep["timings"]["compare_seconds"] > 0
        assert "Camera comparison: Statue_compare.png" in scene["relight_last_bake"]
        assert scene.render.engine == engine and scene.render.filepath == filepath   # restored
        assert [b["kind"] for b in object_bakes(ground)] == ["transport_texture"]
        # the Sun Size the bake took: the scene's Sun's (Scene's Sun, the default), as the
        # CLI's bake-textures takes it; the statue scene has none, so 2 degrees
        assert props.scene_sun_size and rep["settings"]["sun_angle"] == 2.0
        assert rep["from_scene"]["sun_angle"] == 2.0 and rep["from_scene"]["no_sun"]
        tables = lambda: exrio.read_exr(str(tmp_path / "Statue_preview_tables.exr"))[0]["R"]
        before = tables().copy()
        props.sun_angle = 20.0                 # the field is not in use: nothing changes
        assert np.array_equal(tables(), before)
        props.scene_sun_size = False           # update callback re-tabulates, no bake
        after = tables().copy()
        assert not np.allclose(before, after)
        # a Sun in the scene: its Angle is the preview's Sun Size; the tables equal the
        # field's at the same size
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
        scene.collection.objects.link(sun)
        sun.data.angle = np.radians(20.0)
        props.scene_sun_size = True
        assert np.allclose(tables(), after, rtol=1e-6, atol=1e-7)
        sun.data.angle = np.radians(0.526)     # (Blender's default)
        props.scene_sun_size = True            # (the update runs on a set)
        assert not np.allclose(tables(), after)
        bpy.data.objects.remove(sun)
        props.scene_sun_size = False
        assert np.allclose(tables(), after, rtol=1e-6, atol=1e-7)
        assert sorted(os.listdir(tmp_path)) == files
        # previews of different bakes coexist in one material (issue 12: a vertex transport
        # bake silently replaced the texture preview) and Show Preview switches between them
        from relightable_textures.operators.preview.preview_nodes import preview_kinds

        bpy.context.view_layer.objects.active = statue_obj
        props.vertex_directions, props.output_dir = "cube:2", str(tmp_path / "vt") + os.sep
        assert bpy.ops.relight.bake_transport() == {"FINISHED"}
        assert preview_kinds(statue_obj) == ["eigentransport", "transport_texture"]
        group_before = [n.node_tree.name for n in statue_obj.active_material.node_tree.nodes
                        if n.bl_idname == "ShaderNodeGroup" and n.get("relight_preview")]
        assert bpy.ops.relight.show_preview(kind="transport_texture") == {"FINISHED"}
        assert preview_kinds(statue_obj) == ["transport_texture", "eigentransport"]
        # switched, not rebuilt: the same node group, and the vertex preview's nodes stay
        assert [n.node_tree.name for n in statue_obj.active_material.node_tree.nodes
                if n.bl_idname == "ShaderNodeGroup" and n.get("relight_preview")] == group_before
        assert bpy.ops.relight.show_preview(kind="eigentransport") == {"FINISHED"}
        assert preview_kinds(statue_obj)[0] == "eigentransport"
        assert sorted(os.listdir(tmp_path)) == sorted(files + ["vt"])
        files = sorted(files + ["vt"])
        # Remove Preview takes everything out (issue 12: group, atlas images and sliders
        # were left behind): the tagged nodes and their drivers, our unused groups and images,
        # and the sliders once no material shows a preview; the user's nodes stay
        tag = "relight_preview"
        user_nodes = {m.name: sorted(n.name for n in m.node_tree.nodes if not n.get(tag))
                      for m in bpy.data.materials if m.node_tree}
        assert any(g.get(tag) for g in bpy.data.node_groups)
        assert any(i.get(tag) for i in bpy.data.images) and "relight_azimuth" in scene
        for o in (statue_obj, ground):
            bpy.context.view_layer.objects.active = o
            assert bpy.ops.relight.remove_preview() == {"FINISHED"}
        for m in bpy.data.materials:
            if m.node_tree:
                assert not [n for n in m.node_tree.nodes if n.get(tag)]
                assert sorted(n.name for n in m.node_tree.nodes) == user_nodes[m.name]
                assert not (m.node_tree.animation_data and m.node_tree.animation_data.drivers)
        assert not [g for g in bpy.data.node_groups if g.get(tag)]
        assert not [i for i in bpy.data.images if i.get(tag)]
        from relightable_textures.operators.preview.preview_nodes import COLOR_SLIDER, SLIDERS

        assert not [k for k in (*SLIDERS, COLOR_SLIDER) if k in scene]
        assert scene["relight_sample"] == "statue"          # not ours to remove
        # Show Preview reinstalls it from the existing bake's files, without baking
        store = tmp_path / "Statue_transport_texture.npy"
        stamp = (store.stat().st_mtime_ns, (tmp_path / "Statue_texture_report.json").read_bytes())
        bpy.context.view_layer.objects.active = statue_obj
        assert bpy.ops.relight.show_preview(kind="transport_texture") == {"FINISHED"}
        assert (store.stat().st_mtime_ns,
                (tmp_path / "Statue_texture_report.json").read_bytes()) == stamp
        assert any(n.get(tag) and n.bl_idname == "ShaderNodeGroup"
                   for n in statue_obj.active_material.node_tree.nodes)
        assert "relight_azimuth" in scene and sorted(os.listdir(tmp_path)) == files
        # a kind the object has no bake of: one clear error, nothing changed
        with pytest.raises(RuntimeError, match="no steerable texture bake"):
            bpy.ops.relight.show_preview(kind="steerable_texture")
    finally:
        relightable_textures.unregister()


def test_new_scene_holds_the_preset_it_names_and_edits_make_it_custom(fresh_scene):
    """Issue 12: a new scene said "Balanced" while its fields held other values (the preset was
    applied only when the dropdown changed). Now the fields start on the balanced preset of
    either method, the panel's settings equal what the preset's measured figures used
    (components included), and any edit is reported as Custom with the field's name."""
    import relightable_textures
    from relightable_textures.operators.ui import properties as pr
    from relightable_textures.operators.bakes import texture_transport as tx

    relightable_textures.register()
    try:
        props = fresh_scene.relight
        assert props.method == "transport" and props.preset == "balanced"
        assert pr.preset_differences(props) == []
        want = tx.settings_from_preset("balanced")
        got = pr.transport_settings_from_scene(props)
        fields = ("directions", "resolution", "indirect_resolution", "indirect_samples",
                  "components", "bounces", "table_size", "horizon_azimuths",
                  "horizon_resolution")
        for name in fields:
            assert getattr(got, name) == getattr(want, name), name
        props.preset = "production"          # its indirect resolution and table size too
        got, want = pr.transport_settings_from_scene(props), tx.settings_from_preset("production")
        assert pr.preset_differences(props) == []
        for name in fields:
            assert getattr(got, name) == getattr(want, name), name
        props.preset = "balanced"
        props.resolution = 128
        assert pr.preset_differences(props) == ["resolution"]
        # a larger texture scales the preset's indirect grid with it, as the CLI's --preset
        # balanced --resolution 2048 does; a value of one's own stays
        props.resolution = 2048
        got = pr.transport_settings_from_scene(props)
        want = tx.settings_from_preset("balanced", resolution=2048)
        assert (got.indirect_resolution, got.horizon_resolution) == \
            (want.indirect_resolution, want.horizon_resolution) == (512, 0)
        props.resolution = 512
        assert props.indirect_resolution == 256
        props.indirect_resolution = 96
        props.resolution = 1024
        assert props.indirect_resolution == 96
        props.resolution = 128
        assert pr.preset_differences(props) == ["resolution", "indirect_resolution"]
        props.preset = "draft"                       # choosing a preset applies it
        assert pr.preset_differences(props) == []
        assert pr.transport_settings_from_scene(props).components == 48
        assert pr.transport_settings_from_scene(props).horizon_azimuths == \
            tx.settings_from_preset("draft").horizon_azimuths == 64
        props.preset = "production"                  # and back: the field default again
        assert pr.transport_settings_from_scene(props).horizon_azimuths == 128
        props.preset = "draft"
        props.method = "lobes"                       # the lobes preset of the same name
        assert pr.preset_differences(props) == []
        props.order = 9
        assert pr.preset_differences(props) == ["order"]
    finally:
        relightable_textures.unregister()


def test_target_error_pilot_chooses_directions_and_reports_what_it_achieved(bumps, tmp_path):
    """--target-error: the pilot tries direction counts cheapest first, stops at the first that
    meets the target on its small bake, and the report states the choice and the error the
    real bake achieved against its own truths."""
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    scene, obj = bumps
    s = settings(components=None, tol=0.02, bounces=1, indirect_resolution=8,
                 indirect_samples=4)
    reports = run(tx.bake_job(scene, [obj], s, str(tmp_path), truth=0, truth_samples=16,
                              target_error=0.35, preview=False)).reports
    te = reports[0]["target_error"]
    tried = te["tried"]
    assert tried[0]["directions"].startswith("hemi:64")
    assert te["met_in_pilot"] == (tried[-1]["rel_rmse"] <= 0.35)
    assert all(t["rel_rmse"] > 0.35 for t in tried[:-1])
    assert reports[0]["direction_set"] == te["chosen_directions"]
    assert te["tol"] == pytest.approx(0.35 / 3, abs=1e-4)
    assert te["met"] == (te["achieved"] <= 0.35)
    assert len(reports[0]["ground_truth"]["lights"]) == 4       # forced on by the target
    assert te["scored"] == "the viewport"                       # a PCA model: its preview


def test_target_error_pilot_out_of_reach_takes_the_fewest_directions_near_the_best(bumps,
                                                                                   tmp_path):
    """A target no count meets on the pilot's bake: every count is tried, and the choice is the
    fewest directions whose error is within PILOT_PLATEAU of the best tried (more directions
    bought nothing), said in ``why``; never a count above the best one."""
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    scene, obj = bumps
    te = run(tx.pilot(scene, [obj], settings(components=None, tol=0.02), 1e-4, str(tmp_path),
                      resolution=16, truth_samples=16))
    errs = [t["rel_rmse"] for t in te["tried"]]
    assert len(errs) == len(tx.PILOT_COUNTS) and not te["met_in_pilot"]
    pick = [t["directions"] for t in te["tried"]].index(te["chosen_directions"])
    assert errs[pick] <= tx.PILOT_PLATEAU * min(errs)
    assert all(e > tx.PILOT_PLATEAU * min(errs) for e in errs[:pick])
    assert pick <= errs.index(min(errs)) and "bought nothing" in te["why"]


def test_cli_bakes_an_object_of_a_scene_that_is_not_the_active_one(tmp_path):
    """A file saved with another scene active (e.g. after *Add Sample Scene*) bakes the object
    in its own scene (it crashed with "cannot be selected because it is not in View Layer");
    objects of two different scenes cannot be baked together: one line, exit 2."""
    import bpy

    from relightable_textures.operators import cli

    blend = str(tmp_path / "m.blend")
    assert cli.run(["scene", "bumps", "--out", blend]) == 0
    bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
    other = bpy.data.scenes.new("Other")
    lone = bpy.data.objects.new("Lone", bpy.data.meshes.new("Lone"))
    other.collection.objects.link(lone)
    bpy.context.window_manager.windows[0].scene = other
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
    assert bpy.context.scene.name == "Other"
    args = ["bake-textures", blend, "--object", "Bumps", "--directions", "hemi:16",
            "--resolution", "8", "--indirect-resolution", "8", "--indirect-samples", "2"]
    assert cli.run(args) == 0
    rep = json.loads((tmp_path / "m_relight" / "Bumps_texture_report.json").read_text())
    assert rep["directions"] == 16 + 1                       # 1 under the horizon
    assert cli.run(args + ["--object", "Lone", "--force"]) == 2


def test_cli_bake_interrupted_by_sigint_resumes_with_the_same_command(tmp_path):
    """Ctrl-C (SIGINT) during `relight bake-textures`: exit 130, no bake file, the finished
    chunks kept; the same command again reuses them (``chunks_reused`` > 0 in the report and on
    stdout) and its T equals an uninterrupted bake's (``--no-resume``, another folder)."""
    import signal
    import subprocess
    import time

    from relight_cli import BIN, make_scene, relight

    blend = tmp_path / "b.blend"
    make_scene("bumps", blend)
    args = ["bake-textures", str(blend), "--object", "Bumps", "--directions", "hemi:400",
            "--resolution", "16", "--bounces", "0", "--model", "none", "--no-compare",
            "--direct", "cycles"]                  # chunks are what Cycles calls keep
    out = tmp_path / "b_relight"
    proc = subprocess.Popen([str(BIN / "relight"), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if list(out.glob(".relight_cache/Bumps/*/direct_*.npy")):
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-2000:]
    assert "resumes from them" in err
    assert sorted(os.listdir(out)) == [".relight_cache"]        # no bake file was written
    r = relight(*args)
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((out / "Bumps_texture_report.json").read_text())
    assert rep["chunks_total"] == 28 and 0 < rep["chunks_reused"] < 28   # 400 + 35 under
    assert f"resumed: {rep['chunks_reused']} of 28 chunks" in r.stdout
    assert ".relight_cache" not in os.listdir(out)
    ref = tmp_path / "ref"
    assert relight(*args, "--no-resume", "--out", ref).returncode == 0
    np.testing.assert_array_equal(np.load(out / "Bumps_transport_texture.npy"),
                                  np.load(ref / "Bumps_transport_texture.npy"))


def test_panel_lists_the_chunks_a_cancelled_bake_kept_and_discards_them(bumps, tmp_path):
    """After a cancelled bake the panel says how many chunks the next Bake resumes from
    (bake_ops.kept_chunks, drawn by the Bake panels) and *Discard Kept Chunks* deletes them."""
    import bpy

    import relightable_textures
    from relightable_textures.operators.ui import bake_ops
    from relightable_textures.operators.bakes import texture_transport as tx

    scene, obj = bumps
    relightable_textures.register()
    try:
        scene.relight.output_dir = str(tmp_path) + os.sep
        bpy.context.view_layer.objects.active = obj
        assert bake_ops.kept_chunks(bpy.context) == []
        gen = tx.bake_transport_textures(scene, [obj], settings(model="none", direct="cycles"),
                                         str(tmp_path))
        for _ in range(1 + 20):                     # the albedo and 20 directions: 1 chunk
            next(gen)
        gen.close()
        ((folder, n),) = bake_ops.kept_chunks(bpy.context)
        assert n == 1 and folder == str(tmp_path / tx.CACHE_FOLDER / "Bumps")
        assert bpy.ops.relight.discard_chunks() == {"FINISHED"}
        assert bake_ops.kept_chunks(bpy.context) == [] and os.listdir(tmp_path) == []
    finally:
        relightable_textures.unregister()


def _sky_world(scene, env, rotation_deg):
    """A world lit by ``env`` (H, W, 3 bottom row first) through a Point Mapping turned about z."""
    import math

    import bpy

    h, w = env.shape[:2]
    img = bpy.data.images.new("test sky", w, h, float_buffer=True, alpha=False)
    img.colorspace_settings.name = "Non-Color"
    rgba = np.concatenate([env, np.ones((h, w, 1), np.float32)], -1)
    img.pixels.foreach_set(rgba.ravel())
    from relightable_textures.operators.base.compat import ensure_node_tree

    world = bpy.data.worlds.new("test world")
    nodes, links = ensure_node_tree(world).nodes, world.node_tree.links
    tex = nodes.new("ShaderNodeTexEnvironment")
    tex.image = img
    coord = nodes.new("ShaderNodeTexCoord")
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(rotation_deg))
    links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    links.new(tex.outputs["Color"], nodes["Background"].inputs["Color"])
    scene.world = world
    return world, mapping


def _smooth_sky(h=32):
    v = (np.arange(h) + 0.5) / h                      # bottom first
    u = (np.arange(2 * h) + 0.5) / (2 * h)
    el = (v - 0.5) * np.pi
    sky = np.where(el[:, None] > 0, 1.0 + 0.8 * np.cos(2 * np.pi * u)[None, :]
                   * np.cos(el)[:, None], 0.0)
    return np.stack([sky, 0.7 * sky, 0.4 * sky], -1).astype(np.float32)


@pytest.mark.version_sensitive
@pytest.mark.parametrize("indirect", ["gather", "steerable"])
def test_world_lit_preview_rendered_by_cycles_equals_numpy_relight(bumps, tmp_path, indirect):
    """Texture Light = World: the environment groups (constant coefficients written from
    Python, indirect steered by the environment) rendered by Cycles equal the NumPy twin of the
    half-float atlases, and that twin equals relight_environment of the model to half-float
    storage; turning the world's Mapping re-writes the coefficients through the depsgraph
    handler; switching back to Sun restores the sun groups and their render."""
    import bpy

    import relightable_textures
    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.lt_addon.io.atlas import unpack_atlas
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.preview import transport_preview as tp
    from relightable_textures.operators.base.jobs import run

    scene, obj = bumps
    relightable_textures.register()
    try:
        s = settings(components=12, bounces=1, indirect_resolution=R, indirect_samples=4,
                     indirect=indirect, indirect_rays=16, indirect_components=7)
        reports = run(tx.bake_job(scene, [obj], s, str(tmp_path), truth=0)).reports
        prev = reports[0]["preview"]
        bake, store, _ = tx.load_bake(reports[0]["report"])
        assert bake.indirect is not None and bake.indirect.resolution == R
        ntile = prev["tiles"]
        eig = unpack_atlas(np.stack([exrio.read_exr(prev["eigen"])[0][c] for c in "RGB"], -1),
                           ntile + 1, R)
        env = _smooth_sky()
        world, mapping = _sky_world(scene, env, 40.0)
        sun_img = render_rgb(scene, tmp_path, R)
        scene.world = world                       # render_rgb takes the world away
        scene.relight.texture_light = "WORLD"
        timings = tp.update_environment_previews(scene)
        assert timings["warnings"] == [] and timings[obj.name]["update_ms"] < 50
        assert {n.node_tree.name for n in tp._group_nodes(obj, list(bpy.data.node_groups))} == {
            f"Relight Transport env ({obj.name})", f"Relight Transport env indirect ({obj.name})"}
        # the NumPy twin from the half-float atlases against the model relit in NumPy
        ind_atlas = exrio.read_exr(prev["indirect_eigen"] if indirect == "gather" else
                                   os.path.splitext(reports[0]["files"]["indirect"])[0]
                                   + "_atlas.exr")[0]
        ind = unpack_atlas(np.stack([ind_atlas[c] for c in "RGB"], -1),
                           len(bake.indirect.basis_images), R)
        for rot in (40.0, -75.0):
            mapping.inputs["Rotation"].default_value[2] = np.radians(rot)
            bpy.context.view_layer.update()       # the handler sees the world change
            B = gt.direction_matrix(bake.indirect, store.directions)
            C, G = tp.env_coefficients(bake.model.V, B, store.directions, env, -rot)
            twin = tp.viewport_relight_env(eig, C, ind, G)
            want = tx.relight_environment(bake, store, env, -rot, row_order="bottom_first",
                                          source="model")
            assert rel(twin, want) < 3e-3            # half-float atlases
            img = render_rgb(scene, tmp_path, R)
            scene.world = world
            assert twin.max() > 0.05
            assert np.abs(img - twin).max() <= 2.0 ** -10 * twin.max(), rot
        # Environment Rotation adds to the Mapping's (its update callback rewrites the values)
        group = bpy.data.node_groups[f"Relight Transport env ({obj.name})"]
        scene.relight.env_rotation = 30.0
        C, _ = tp.env_coefficients(bake.model.V, None, store.directions, env, -(rot + 30.0))
        padded = np.zeros((3, 3 * ntile))
        padded[:, :C.shape[1]] = C
        np.testing.assert_allclose(np.array(group[tp.ENV_VALUES]),
                                   padded.reshape(3, ntile, 3).transpose(1, 0, 2).ravel(),
                                   rtol=1e-6, atol=2e-8)      # (float32 node values)
        # the rotation moved the light (the sky is brighter towards one azimuth)
        assert rel(render_rgb(scene, tmp_path, R), sun_img) > 0.05
        scene.world = world
        scene.relight.texture_light = "SUN"
        np.testing.assert_allclose(render_rgb(scene, tmp_path, R), sun_img, atol=1e-6)
        # Remove Preview takes both light modes' groups away
        from relightable_textures.operators.preview import preview_nodes as pn

        pn.remove_preview(obj, scene)
        assert not [g for g in bpy.data.node_groups if g.name.startswith("Relight Transport")]
    finally:
        relightable_textures.unregister()


def test_every_bake_reports_how_far_the_viewport_model_is_from_T(bumps, tmp_path):
    """report["model_vs_T"]: the PCA at full rank is T (0 to half-float eigen-textures), a
    2-component PCA is far from it; no Cycles truth is needed."""
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    scene, obj = bumps
    full = run(tx.bake_job(scene, [obj], settings(components=S, viewport="pca"),
                           str(tmp_path / "full"), truth=0, preview=False)).reports[0]["model_vs_T"]
    assert full["headline"] < 2e-3 and full["viewport"] == "pca"
    assert [r["elevation"] for r in full["lights"]] == [10.0, 30.0, 55.0, 80.0]
    low = run(tx.bake_job(scene, [obj], settings(components=2, viewport="pca"),
                          str(tmp_path / "low"), truth=0, preview=False)).reports[0]["model_vs_T"]
    assert low["headline"] > 0.05 and low["worst"]["rel"] >= low["headline"]
    # the transport viewport shows T through 64^2 sparse tables, however poor the PCA: only
    # the tables' bilinear error remains (measured 0.008 here; bumps demo at 400 directions
    # 0.005), while the same 2-component PCA stays as far as before
    view = run(tx.bake_job(scene, [obj], settings(components=2, viewport="transport"),
                           str(tmp_path / "view"), truth=0, preview=False)).reports[0]["model_vs_T"]
    assert view["viewport"] == "transport" and view["headline"] < 0.02
    assert view["model_headline"] == low["headline"]


def test_a_preview_of_many_components_fits_cycles_svm_stack(bumps, tmp_path):
    """150 components (50 tiles, the production preset has 86): Cycles compiled every lookup
    before the first sum and failed with "out of SVM stack space" from about 40 tiles (black
    render). The group chains each tile's lookups after the previous sum; the render equals
    the twin to half precision."""
    from relightable_textures.lt_addon.io import exrio
    from relightable_textures.lt_addon.io.atlas import unpack_atlas
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.preview import transport_preview as tp
    from relightable_textures.operators.base.jobs import run

    scene, obj = bumps
    s = settings(directions="hemi:160:1.5", components=150, viewport="pca")
    prev = run(tx.bake_job(scene, [obj], s, str(tmp_path), truth=0)).reports[0]["preview"]
    assert prev["tiles"] == 50
    eig = unpack_atlas(np.stack([exrio.read_exr(prev["eigen"])[0][c] for c in "RGB"], -1),
                       51, R)
    tab = unpack_atlas(np.stack([exrio.read_exr(prev["tables"])[0][c] for c in "RGB"], -1),
                       50, 16)
    scene["relight_azimuth"], scene["relight_elevation"] = 40.0, 25.0
    img = render_rgb(scene, tmp_path, R)
    want = tp.viewport_relight(eig, tab, direction_from_az_el(40.0, 25.0))
    assert want.max() > 0.05
    assert np.abs(img - want).max() <= 2.0 ** -10 * want.max()
