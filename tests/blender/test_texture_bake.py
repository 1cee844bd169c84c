"""Steerable texture bakes with real Cycles at tiny sizes (32^2, order 5, fixed seeds).

Independent references: fresh Cycles bakes of the same lights, Cycles renders of the preview
node group, and bake-vs-bake noise to justify tolerances.
"""

import os

import numpy as np
import pytest
from render_check import render_rgb

from relightable_textures import samples
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el, disk_to_hemisphere
from relightable_textures.lt_addon.io.storage import reconstruction_error

R, ORDER, SPP, ENV_H = 32, 5, 64, 64


def rel(reference, estimate):
    return reconstruction_error(reference, estimate)["rel_fro"]


@pytest.fixture
def bumps(fresh_scene):
    import bpy

    samples.build("bumps", fresh_scene, "test")
    return fresh_scene, bpy.data.objects["Bumps"]


def settings(**kw):
    from relightable_textures.operators.bakes.steerable_bake import TextureBakeSettings

    base = dict(order=ORDER, resolution=R, samples=SPP, bounces=1, env_height=ENV_H,
                storage="float")
    base.update(kw)
    return TextureBakeSettings(**base)


def bake(scene, obj, **kw):
    from relightable_textures.operators.bakes import steerable_bake as sb

    s = settings(**kw)
    return s, sb.run(sb.bake_steerable_texture(scene, obj, s))


def bake_with_preview(scene, obj, tmp_path, target=None, **kw):
    """Bake ``obj``, write its files to ``tmp_path`` and install the preview on ``target``."""
    from relightable_textures.operators.preview import preview_nodes
    from relightable_textures.operators.bakes import steerable_bake as sb

    s, result = bake(scene, obj, **kw)
    report = sb.write_bake(result, obj, str(tmp_path), s)
    preview_nodes.install_preview(scene, target or obj, report["exr"], result.texture)
    return result


def env_bake(scene, obj, env, spp, seed, sampling="importance"):
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    with EnvironmentBake(scene, obj, R, spp, 1, (ENV_H, 2 * ENV_H), seed=seed,
                         world_sampling=sampling) as session:
        return session.bake(env)


def test_sampled_centre_light_reproduces_its_own_bake(bumps):
    """Steering to a sampled centre gives the bake of that light (exact with the same seed and
    world sampling 'none', where a Cycles bake is a fixed linear function of the image)."""
    from relightable_textures.lt_addon.steerable.sampled_basis import build_sampled_basis

    scene, obj = bumps
    _, result = bake(scene, obj, world_sampling="none")
    tex = result.texture
    sampled = build_sampled_basis(tex.basis)
    for k in [i for i, c in enumerate(tex.centres) if np.hypot(*c) < 0.9][:3]:
        own = env_bake(scene, obj, sampled.light_environment(k, ENV_H, row_order="bottom_first"),
                       SPP, seed=0, sampling="none")
        c, gain = tex.steering_weights(disk_to_hemisphere(tex.centres[k]))
        steered = tex.relight(disk_to_hemisphere(tex.centres[k]), clamp=False) / gain
        assert rel(own, steered) < 1e-5  # float32 solve and sum


def test_bake_is_linear_in_the_light(bumps):
    scene, obj = bumps
    h = np.linspace(-1, 1, ENV_H)[:, None] * np.ones((1, 2 * ENV_H))
    a = (h > 0) * (1.0 + 0.5 * np.cos(6 * h))
    b = (h > 0) * np.sin(9 * h)  # negative radiance included
    ba = env_bake(scene, obj, a, 16, 0, "none")
    bb = env_bake(scene, obj, b, 16, 0, "none")
    bab = env_bake(scene, obj, a + 2 * b, 16, 0, "none")
    assert rel(bab, ba + 2 * bb) < 1e-5
    assert bb.min() < 0  # Cycles really used the negative texels


def test_relight_matches_cycles_truth_of_the_same_light_within_noise(bumps):
    """Tolerance from measured noise: the relit texture may differ from an independent bake of
    the same light by at most 1.3x what two independent bakes differ by (measured ratio <= 1.08
    at 16..256 spp), plus 0.01 for environment discretisation."""
    from relightable_textures.operators.bakes.steerable_bake import truth_directions
    from relightable_textures.operators.bakes.steerable_truth import steered_light_environment

    scene, obj = bumps
    _, result = bake(scene, obj)
    tex = result.texture
    for d in truth_directions(tex, 3):
        env = steered_light_environment(tex, d, ENV_H)
        a = env_bake(scene, obj, env, SPP, seed=101)
        b = env_bake(scene, obj, env, SPP, seed=102)
        relit = tex.relight(d, clamp=False)
        noise = rel(a, b)
        assert rel(a, relit) < 1.3 * noise + 0.01, (rel(a, relit), noise)


@pytest.mark.parametrize("frame", ["world", "tangent"])
def test_preview_node_group_rendered_by_cycles_equals_numpy_relight(bumps, tmp_path, frame):
    """The node group (steering, clamp and calibration computed in nodes, half-float atlas)
    rendered by Cycles through an orthographic top camera equals SteerableTexture.relight to
    half-float precision. The tangent frame is checked on a flat plane carrying the patch UVs."""
    import bpy

    from relightable_textures.lt_addon.geometry import heightfield
    from relightable_textures.operators.base.meshes import grid_faces, mesh_object

    scene, obj = bumps
    target = obj
    if frame == "tangent":
        u, v = heightfield.grid(4)
        verts = np.stack([(u - 0.5) * 2, (v - 0.5) * 2, np.zeros_like(u)], -1).reshape(-1, 3)
        target = mesh_object("Flat", verts, grid_faces(5, 5), scene.collection,
                             uv=np.stack([u, v], -1).reshape(-1, 2))
        target.data.materials.append(bpy.data.materials.new("FlatMaterial"))
    result = bake_with_preview(scene, obj, tmp_path, target, frame=frame, samples=4)
    if frame == "tangent":   # out of the camera's render (a bake of it is refused: issue 59)
        obj.hide_render = True
    az, el, inten, color = 40.0, 35.0, 2.0, (1.0, 0.5, 0.25)
    scene["relight_azimuth"], scene["relight_elevation"] = az, el
    scene["relight_intensity"], scene["relight_color"] = inten, color
    img = render_rgb(scene, tmp_path, R)
    want = result.texture.relight(direction_from_az_el(az, el), inten, color)
    assert want.max() > 0.1
    # half-float precision of the output, plus that of the unit-intensity sum where the clamp at
    # 0 decides differently between the half atlas and float32 NumPy (a flat 1.16e-3 over such
    # texels, measured on an AVX-512 machine; 2^-10 * intensity = 1.95e-3)
    assert np.abs(img - want).max() <= 2.0 ** -10 * (want.max() + inten)


def test_preview_follows_the_sun_lamp(bumps, tmp_path):
    from relightable_textures.operators.preview import preview_nodes
    from relightable_textures.samples.scene_setup import sun_lamp

    scene, obj = bumps
    result = bake_with_preview(scene, obj, tmp_path, samples=4)
    sun = sun_lamp(scene.collection, elevation_deg=50.0, azimuth_deg=120.0)
    preview_nodes.set_follow_sun(scene, sun)
    scene["relight_follow_sun"] = 1.0
    scene["relight_azimuth"], scene["relight_elevation"] = 0.0, 10.0  # ignored while following
    img = render_rgb(scene, tmp_path, R)
    want = result.texture.relight(direction_from_az_el(120.0, 50.0))
    assert np.abs(img - want).max() <= 2.0 ** -10 * want.max()


def test_cancel_keeps_the_previous_bake_and_rebake_replaces_it(bumps, tmp_path):
    import bpy

    from relightable_textures.operators.preview import preview_nodes
    from relightable_textures.operators.bakes import steerable_bake as sb
    from relightable_textures.operators.base.blend_files import object_bakes

    scene, obj = bumps
    result = bake_with_preview(scene, obj, tmp_path, samples=4)
    files = {n: (tmp_path / n).read_bytes() for n in os.listdir(tmp_path)}
    record = object_bakes(obj)
    nodes = sorted(n.name for n in obj.active_material.node_tree.nodes)
    world, images = scene.world, sorted(i.name for i in bpy.data.images)

    steps = []
    gen = sb.bake_steerable_texture(scene, obj, settings(samples=8, order=4))
    assert sb.run(gen, on_progress=steps.append, should_cancel=lambda: len(steps) >= 3) is None
    assert len(steps) == 3 and steps[-1].total == 17
    assert {n: (tmp_path / n).read_bytes() for n in os.listdir(tmp_path)} == files
    assert object_bakes(obj) == record
    assert sorted(n.name for n in obj.active_material.node_tree.nodes) == nodes
    assert scene.world == world and sorted(i.name for i in bpy.data.images) == images
    assert not [o for o in bpy.data.objects if o.name.startswith("RelightBake")]

    # a re-bake sees the user's material, not the emission preview now wired into it
    s_same, again = bake(scene, obj, samples=4)
    np.testing.assert_allclose(again.texture.basis_images, result.texture.basis_images,
                               rtol=1e-5, atol=1e-6)
    s2, result2 = bake(scene, obj, samples=4, order=4)
    report2 = sb.write_bake(result2, obj, str(tmp_path), s2)
    preview_nodes.install_preview(scene, obj, report2["exr"], result2.texture)
    bakes = object_bakes(obj)
    assert len(bakes) == 1 and bakes[0]["order"] == 4
    assert sorted(os.listdir(tmp_path)) == sorted(files)  # replaced in place, no temporaries
    assert len([n for n in obj.active_material.node_tree.nodes if n.get("relight_preview")
                and n.bl_idname == "ShaderNodeGroup"]) == 1


def test_bad_objects_are_refused_with_clear_errors(fresh_scene):
    import bpy

    from relightable_textures.operators.base.cycles_bake import BakeInputError, check_bakeable
    from relightable_textures.operators.base.meshes import mesh_object

    samples.build("statue", fresh_scene, "test")
    with pytest.raises(BakeInputError, match="not a mesh"):
        check_bakeable(bpy.data.objects["Camera"])
    no_uv = mesh_object("NoUV", np.eye(3), np.array([[0, 1, 2]]), fresh_scene.collection)
    with pytest.raises(BakeInputError, match="no UV map"):
        check_bakeable(no_uv)
    with pytest.raises(BakeInputError, match="order"):
        settings(order=13).validate()
    with pytest.raises(BakeInputError, match="memory"):
        settings(order=12, resolution=8192).validate()


def test_environment_orientation_agrees_with_a_cycles_sun_lamp(bumps):
    """Relit under azimuth az, the texture must resemble a real Cycles Sun lamp from az far more
    than Suns from the mirrored azimuths (catches any flip of the equirect convention)."""
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from relightable_textures.operators.bakes.steerable_truth import equivalent_sun_angle_deg

    scene, obj = bumps
    _, result = bake(scene, obj, samples=128, order=7)
    tex = result.texture
    angle = equivalent_sun_angle_deg(tex)
    with EnvironmentBake(scene, obj, R, 128, 1, (ENV_H, 2 * ENV_H), seed=5) as session:
        suns = {az: session.bake_sun(direction_from_az_el(az, 35.0), 1.0, angle)
                for az in (20.0, 110.0, 200.0, 340.0)}
    for az, mirrors in ((20.0, (200.0, 340.0)), (110.0, (200.0, 340.0))):
        relit = tex.relight(direction_from_az_el(az, 35.0))
        right = rel(suns[az], relit)
        assert right < 0.25, right
        for m in mirrors:
            assert rel(suns[m], relit) > 2 * right


def test_calibrated_flat_plane_follows_the_cosine_law_in_cycles(fresh_scene):
    """Units and calibration checked by Cycles itself: a flat Lambertian plane (albedo 0.8)
    relit with intensity 1 must give outgoing radiance 0.8 cos(theta0) / pi, which is also what
    a Cycles Sun lamp of strength 1 gives. Tolerance 2% of the zenith value: texel-averaged
    Monte Carlo noise at 64 spp measured below 0.5%."""
    import bpy

    from relightable_textures.lt_addon.geometry import heightfield
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake
    from relightable_textures.operators.base.meshes import grid_faces, mesh_object
    from relightable_textures.samples.scene_setup import diffuse_material

    u, v = heightfield.grid(4)
    verts = np.stack([(u - 0.5) * 2, (v - 0.5) * 2, np.zeros_like(u)], -1).reshape(-1, 3)
    plane = mesh_object("Flat", verts, grid_faces(5, 5), fresh_scene.collection,
                        uv=np.stack([u, v], -1).reshape(-1, 2))
    plane.data.materials.append(diffuse_material("Grey", (0.8, 0.8, 0.8)))
    _, result = bake(fresh_scene, plane, order=7)
    zenith = 0.8 / np.pi
    with EnvironmentBake(fresh_scene, plane, R, 1, 0, (ENV_H, 2 * ENV_H)) as session:
        for el in (15.0, 50.0, 80.0):
            d = direction_from_az_el(70.0, el)
            want = 0.8 * np.sin(np.radians(el)) / np.pi
            relit = result.texture.relight(d)
            assert abs(relit.mean() - want) < 0.02 * zenith, (el, relit.mean(), want)
            sun = session.bake_sun(d, 1.0, 0.0)  # hard sun: noise-free at 1 spp
            assert abs(sun.mean() - want) < 1e-3 * zenith


def test_overlapping_uvs_are_reported_before_baking(fresh_scene):
    """Two quads mapped onto the same UV square: every covered texel overlaps; the bake warns
    through its progress stream (operator report / CLI line) and records it in the figures."""
    from relightable_textures.operators.bakes import steerable_bake as sb
    from relightable_textures.operators.base.meshes import mesh_object

    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                      [2, 0, 0], [3, 0, 0], [3, 1, 0], [2, 1, 0]], dtype=float)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]] * 2, dtype=float)
    obj = mesh_object("Twins", verts, np.array([[0, 1, 2, 3], [4, 5, 6, 7]]),
                      fresh_scene.collection, uv=uv)
    steps = []
    result = sb.run(sb.bake_steerable_texture(fresh_scene, obj, settings(order=2, samples=1,
                                                                        resolution=16)),
                    on_progress=steps.append)
    assert steps[0].message.startswith("warning:") and "overlapping UVs" in steps[0].message
    assert result.figures["uv_layout"]["overlapping"] == pytest.approx(1.0)
    assert result.figures["uv_layout"]["covered"] == pytest.approx(1.0)


def test_lobes_job_reports_a_camera_comparison_or_says_why_not(bumps, tmp_path):
    """The report's picture (issue 12): with a scene camera, the preview next to a Cycles Sun
    render of the lowest held-out light, captioned, its own rel. RMSE recomputed here from the
    PNG's panels being different pictures; without a camera, a line saying so (the labelled
    UV contact sheet is the fallback) and no PNG."""
    from matplotlib.image import imread

    from relightable_textures.lt_addon.io.label import GLYPH_H
    from relightable_textures.operators.bakes import steerable_bake as sb

    scene, obj = bumps
    s = settings(order=3, resolution=16, samples=4, bounces=0)
    out = sb.run(sb.lobes_job(scene, obj, s, str(tmp_path), truth=2,
                              sheet_path=str(tmp_path / "sheet.png")))
    assert isinstance(out.texture, sb.SteerableTexture) and out.report["object"] == "Bumps"
    cmp = out.report["comparison"]
    low = min(out.report["ground_truth"]["directions"], key=lambda r: r["elevation"])
    assert (cmp["azimuth"], cmp["elevation"]) == (low["azimuth"], low["elevation"])
    assert cmp["truth_samples"] == 16 and 0 < cmp["rel_rmse_covered_pixels"] < 2
    img = imread(cmp["png"])[..., :3]
    band = (GLYPH_H + 4) * 2
    w = (img.shape[1] - 2 * 4) // 3
    assert max(img.shape[0] - band, w) == 256                 # longer side 256 px
    preview, truth = img[band:, :w], img[band:, w + 4:2 * w + 4]
    assert np.abs(preview - truth).mean() > 0                # two renders, not one twice
    sheet = imread(str(tmp_path / "sheet.png"))
    assert sheet.shape[1] >= 4 * 256                          # 16 texels enlarged to be read
    assert out.report["timings"]["wall_total"] >= out.report["timings"]["compare_seconds"] > 0

    camera, scene.camera = scene.camera, None
    try:
        again = sb.run(sb.lobes_job(scene, obj, s, str(tmp_path / "nocam"), truth=1))
    finally:
        scene.camera = camera
    assert "no camera" in again.report["comparison"]["skipped"]
    assert not [n for n in os.listdir(tmp_path / "nocam") if n.endswith(".png")]
