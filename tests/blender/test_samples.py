"""Sample scenes build deterministically with real bpy, and their geometry is what we intend."""

import hashlib

import numpy as np
import pytest

from relightable_textures import samples
from relightable_textures.lt_addon.geometry import heightfield

#: Also run on 5.2 LTS by the matrix: the sample scenes' materials and worlds
#: (compat.ensure_node_tree).
pytestmark = pytest.mark.version_sensitive

EXPECTED_VERTICES = {  # (test, demo) vertex counts of the object to relight
    "bumps": (33 * 33, 129 * 129),
    "noise": (33 * 33, 129 * 129),
    "statue": (507, 4421),
    "room": (26, 98),
}


def _fingerprint(scene_name, size):
    import bpy

    from relightable_textures.operators.base.meshes import vertex_positions, world_bounds

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    info = samples.build(scene_name, bpy.context.scene, size)
    result = {}
    for obj in bpy.data.objects:
        if obj.type == "MESH":
            co = vertex_positions(obj)
            result[obj.name] = (len(co), world_bounds(obj).round(9).tolist(),
                                hashlib.sha256(co.astype(np.float32).tobytes()).hexdigest(),
                                [uv.name for uv in obj.data.uv_layers])
    return info, result


@pytest.mark.parametrize("name", samples.SCENES)
@pytest.mark.parametrize("size", samples.SIZES)
def test_sample_builds_deterministically(name, size):
    info_a, meshes_a = _fingerprint(name, size)
    info_b, meshes_b = _fingerprint(name, size)
    assert info_a == info_b
    assert meshes_a == meshes_b
    count = meshes_a[info_a["relight_object"]][0]
    assert count == EXPECTED_VERTICES[name][samples.SIZES.index(size)]
    for mesh_name, (_, _, _, uv_maps) in meshes_a.items():
        assert uv_maps == ["UVMap"], f"{mesh_name} lacks a UV map"


def test_sample_scene_settings_are_explicit(fresh_scene):
    import bpy

    samples.build("bumps", fresh_scene, "test")
    cyc = fresh_scene.cycles
    assert fresh_scene.render.engine == "CYCLES"
    assert (cyc.seed, cyc.use_adaptive_sampling, cyc.use_denoising) == (0, False, False)
    assert cyc.sample_clamp_indirect == 0.0 and cyc.samples == 16
    assert fresh_scene.world.cycles.sampling_method == "NONE"
    assert fresh_scene["relight_sample"] == "bumps"
    assert bpy.data.objects["TopCamera"].data.type == "ORTHO"


def test_bumps_vertices_follow_the_height_field(fresh_scene):
    """Each vertex height equals the analytic field at its UV (an independent evaluation)."""
    import bpy

    from relightable_textures.operators.base.meshes import (corner_vertices, uv_corners,
                                                            vertex_positions)

    samples.build("bumps", fresh_scene, "test")
    mesh = bpy.data.objects["Bumps"].data
    co = vertex_positions(bpy.data.objects["Bumps"])
    vertex_uv = np.zeros((len(co), 2))
    vertex_uv[corner_vertices(mesh)] = uv_corners(mesh, mesh.uv_layers["UVMap"])
    expected = 2.0 * heightfield.bumps_and_dents(vertex_uv[:, 0], vertex_uv[:, 1])
    np.testing.assert_allclose(co[:, 2], expected, atol=1e-5)  # float32 UV / position storage
    np.testing.assert_allclose(co[:, :2], (vertex_uv - 0.5) * 2.0, atol=1e-6)
    assert co[:, 2].max() > 0.1 and co[:, 2].min() < -0.1  # both bumps and dents present


@pytest.mark.parametrize("azimuth, elevation", [(30.0, 45.0), (200.0, 10.0), (0.0, 90.0)])
def test_sun_lamp_points_from_its_azimuth_and_elevation(fresh_scene, azimuth, elevation):
    import math

    from mathutils import Vector

    from relightable_textures.samples import scene_setup

    sun = scene_setup.sun_lamp(fresh_scene.collection, elevation, azimuth)
    fresh_scene.view_layers[0].update()
    travel = sun.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))  # a sun shines along local -z
    el, az = math.radians(elevation), math.radians(azimuth)
    towards_light = (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))
    np.testing.assert_allclose(-np.array(travel), towards_light, atol=1e-6)


def test_camera_looks_at_its_target(fresh_scene):
    from mathutils import Vector

    from relightable_textures.samples import scene_setup

    loc, target = (1.0, -4.0, 2.0), (0.5, 0.5, 0.3)
    cam = scene_setup.perspective_camera(fresh_scene, fresh_scene.collection, loc, target)
    fresh_scene.view_layers[0].update()
    look = cam.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))
    want = np.subtract(target, loc)
    np.testing.assert_allclose(np.array(look), want / np.linalg.norm(want), atol=1e-6)


def test_unknown_scene_and_size_raise(fresh_scene):
    with pytest.raises(ValueError, match="unknown sample scene"):
        samples.build("castle", fresh_scene, "test")
    with pytest.raises(ValueError, match="unknown size"):
        samples.build("bumps", fresh_scene, "huge")


@pytest.mark.parametrize("name", ["statue", "room"])
def test_object_scenes_have_a_sky_whose_rotation_shows(fresh_scene, tmp_path, name):
    """Issue 12: the demo's constant white world made the Environment Rotation slider look
    broken (a constant sky is the same when rotated). The object scenes get a sun-and-sky HDR,
    packed into the .blend as float (it survives saving), behind a Mapping node the preview
    follows; turning it by 90 degrees moves most of the light."""
    import bpy

    from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
    from relightable_textures.lt_addon.transport.eigentransport import (
        project_environment, rotate_environment_samples, sample_equirect)
    from relightable_textures.operators.preview import vertex_relight as vr

    samples.build(name, fresh_scene, "test")
    path = str(tmp_path / "s.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    env = vr.world_environment(scene)
    assert env is not None and env.max() > 50 * np.median(env)      # a sun brighter than sky
    assert vr.world_rotation(scene) == (0.0, "")                    # a Mapping the preview follows
    assert scene.world.cycles.sampling_method == "NONE"
    ds = parse_direction_spec("cube:8")
    Lw = project_environment(env, ds.directions, ds.solid_angles, row_order="bottom_first")
    L = sample_equirect(env, ds.directions, row_order="bottom_first")
    turned = rotate_environment_samples(L, ds, np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]))
    assert np.linalg.norm(turned - Lw) > 0.5 * np.linalg.norm(Lw)
