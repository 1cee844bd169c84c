"""Each texel's footprint against a converged Cycles bake (issue 55).

A 1-spp Cycles bake -- and the ray bake with one ray per texel -- samples the texel centre; every
further Cycles sample jitters the point over a box around it inside the centre's triangle
(lt_addon/rays/footprint.py): half a texel a side up to Blender 5.2.0, a whole texel from
5.2.1. Where a shadow edge or a thin triangle passes a texel the two differ, and a grazing sun
on relief is made of such texels. The reference here is Cycles' own 256-spp bake of the same
hard sun (the DIFFUSE direct pass, irradiance: cos x V / pi); the bar is Cycles' own 16-spp
bake's distance from it, per direction (the issue's: within 1.25x).

The scene: a flat-shaded brick relief (a 65 x 65 vertex grid over 2 m, bricks 0.25 x 0.125 m
raised 0.1 m over 3 cm mortar grooves, planar UVs), 64^2. Measured 2026-12-06: the worst of the
four suns 0.95x Cycles' 16-spp distance on bpy 5.0.1 (half-texel box), 0.98x on 5.3.0 (whole
texel); see the asserts' messages for the figures of a run. Version-sensitive: the box changed.
"""

import numpy as np
import pytest

from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el

pytestmark = pytest.mark.version_sensitive

R = 64
SUNS = ((30.0, 2.0), (200.0, 2.0), (30.0, 45.0), (110.0, 45.0))


def relief(scene, n=65, size=2.0, height=0.1):
    """The brick relief of the module docstring, linked into ``scene``."""
    import bpy

    from relightable_textures.operators.base.meshes import grid_faces, mesh_object

    t = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(t, t, indexing="xy")
    row = np.floor((Y + 1) / 0.125)
    gx = np.mod(X + 1 + (row % 2) * 0.125, 0.25)
    gy = np.mod(Y + 1, 0.125)
    H = np.where((gx < 0.03) | (gy < 0.03), 0.0, height)
    V = np.stack([X, Y, H], -1).reshape(-1, 3)
    uv = np.stack([(X + 1) / 2, (Y + 1) / 2], -1).reshape(-1, 2)
    obj = mesh_object("Relief", V, grid_faces(n, n), scene.collection, uv=uv, smooth=False)
    obj.data.materials.append(bpy.data.materials.new("Brick"))
    bpy.context.view_layer.update()
    return obj


def test_the_footprint_is_as_close_to_a_converged_bake_as_16_cycles_samples(fresh_scene):
    from relightable_textures.lt_addon.rays.direct import direct_rows
    from relightable_textures.lt_addon.rays.engine import Occluder
    from relightable_textures.operators.base import ray_scene
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    obj = relief(fresh_scene)
    dirs = np.array([direction_from_az_el(a, e) for a, e in SUNS])
    cyc = {}
    for spp in (16, 256):
        with EnvironmentBake(fresh_scene, obj, R, spp, 0, (8, 16), mode="irradiance", seed=1,
                             world_sampling="none", passes="direct") as session:
            cyc[spp] = [session.bake_sun(d, 1.0, 0.0)[..., 0].reshape(-1) for d in dirs]
    with ray_scene.RenderGeometry(fresh_scene) as depsgraph:
        V, T, _ = ray_scene.casters(depsgraph)
        occluder = Occluder(V, T)
        smp, fp = ray_scene.receiver_points(obj, depsgraph, R)
        _, centre = ray_scene.receiver_points(obj, depsgraph, R, footprint=False)
    rows = direct_rows(occluder, fp, dirs)
    one = direct_rows(occluder, centre, dirs)
    assert fp.footprint.refined > 0 and fp.footprint.rays > 0
    for s, sun in enumerate(SUNS):
        ref = cyc[256][s][smp.texel]
        assert (ref == 0).mean() > 0.02, sun                  # cast shadows at every sun

        def dist(x):
            return float(np.linalg.norm(x - ref) / np.linalg.norm(ref))
        bar = dist(cyc[16][s][smp.texel])
        got, centre_only = dist(rows[s]), dist(one[s])
        msg = f"{sun}: footprint {got:.4f}, centre {centre_only:.4f}, Cycles 16 spp {bar:.4f}"
        print(msg)
        assert got <= 1.25 * bar, msg
        if sun[1] < 10:                   # the centre alone is what the issue measured (0.2)
            assert centre_only > 2 * bar, msg


def test_the_jitter_box_is_the_one_this_blender_bakes_with(fresh_scene):
    """jitter_box(bpy.app.version) against this Blender's own bake: an emission that steps from
    0 to 1 at 0.2 texels right of every texel centre (a function of the UV the bake interpolates
    at the jittered point), baked at 1024 spp; a texel away from the diagonal then holds the
    share of the box past the step, 0.5 - 0.2 / box (0.1 for half a texel, 0.3 for a whole one).
    The noise of 1024 samples of a 0/1 value is 0.016 a texel; the median of 256 texels ~0.001."""
    import bpy

    from relightable_textures.lt_addon.rays.footprint import jitter_box

    R, d = 16, 0.2
    scene = fresh_scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 1024
    scene.cycles.seed = 1
    scene.cycles.use_denoising = False
    from relightable_textures.operators.base.compat import ensure_node_tree
    from relightable_textures.operators.base.meshes import grid_faces, mesh_object

    t = np.array([-1.0, 1.0])
    X, Y = np.meshgrid(t, t, indexing="xy")
    V = np.stack([X, Y, np.zeros_like(X)], -1).reshape(-1, 3)
    uv = np.stack([(X + 1) / 2, (Y + 1) / 2], -1).reshape(-1, 2)
    obj = mesh_object("Step", V, grid_faces(2, 2), scene.collection, uv=uv, smooth=False)
    mat = bpy.data.materials.new("Step")
    nt = ensure_node_tree(mat)
    nt.nodes.clear()
    node = nt.nodes.new
    tc, sep = node("ShaderNodeTexCoord"), node("ShaderNodeSeparateXYZ")
    mul, frac, step = node("ShaderNodeMath"), node("ShaderNodeMath"), node("ShaderNodeMath")
    mul.operation, frac.operation, step.operation = "MULTIPLY", "FRACT", "GREATER_THAN"
    mul.inputs[1].default_value, step.inputs[1].default_value = R, 0.5 + d
    em, out = node("ShaderNodeEmission"), node("ShaderNodeOutputMaterial")
    for a, b in ((tc.outputs["UV"], sep.inputs[0]), (sep.outputs[0], mul.inputs[0]),
                 (mul.outputs[0], frac.inputs[0]), (frac.outputs[0], step.inputs[0]),
                 (step.outputs[0], em.inputs["Color"]), (em.outputs[0], out.inputs["Surface"])):
        nt.links.new(a, b)
    img = bpy.data.images.new("StepBake", R, R, float_buffer=True)
    tex = node("ShaderNodeTexImage")
    tex.image = img
    nt.nodes.active = tex
    obj.data.materials.append(mat)
    for o in scene.objects:
        o.select_set(o is obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.bake(type="EMIT", margin=0)
    share = float(np.median(np.array(img.pixels[:]).reshape(R, R, 4)[..., 0]))
    measured = d / (0.5 - share)
    print(f"bpy {bpy.app.version_string}: past the step {share:.4f}, box {measured:.3f} texels")
    assert measured == pytest.approx(jitter_box(bpy.app.version), abs=0.02), \
        f"Blender {bpy.app.version_string} jitters over {measured:.3f} texels"


def test_smooth_texels_clipped_by_their_triangle(fresh_scene):
    """The smooth demo bumps at 128^2 (triangles of about a texel: most jitter boxes clipped by
    their triangle, whose converged mean is not the centre's value) at two low suns: the
    footprint against Cycles' 256-spp bake, within the issue's 1.25x of Cycles' 16-spp
    distance; the centre alone is several times it. Measured 2026-12-06: bpy 5.0.1 0.80x / 0.90x
    (centre 3.8x / 5.0x), 5.3.0 0.87x / 0.86x (4.2x / 4.6x); see the messages."""
    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.rays.direct import direct_rows
    from relightable_textures.lt_addon.rays.engine import Occluder
    from relightable_textures.operators.base import ray_scene
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    samples.build("bumps", fresh_scene, "demo")
    obj = bpy.data.objects["Bumps"]
    suns = ((60.0, 5.0), (250.0, 10.0))
    dirs = np.array([direction_from_az_el(a, e) for a, e in suns])
    cyc = {}
    for spp in (16, 256):
        with EnvironmentBake(fresh_scene, obj, 128, spp, 0, (8, 16), mode="irradiance", seed=1,
                             world_sampling="none", passes="direct") as session:
            cyc[spp] = [session.bake_sun(d, 1.0, 0.0)[..., 0].reshape(-1) for d in dirs]
    with ray_scene.RenderGeometry(fresh_scene) as depsgraph:
        V, T, _ = ray_scene.casters(depsgraph)
        occluder = Occluder(V, T)
        smp, fp = ray_scene.receiver_points(obj, depsgraph, 128)
        _, centre = ray_scene.receiver_points(obj, depsgraph, 128, footprint=False)
    rows = direct_rows(occluder, fp, dirs)
    one = direct_rows(occluder, centre, dirs)
    # most texels: by rays, or (thin smooth texels away from edges) by their mean normal
    f = fp.footprint
    assert f.refined + f.linear > 0.2 * len(smp.texel) * len(suns) and f.linear > 0
    for s, sun in enumerate(suns):
        ref = cyc[256][s][smp.texel]

        def dist(x):
            return float(np.linalg.norm(x - ref) / np.linalg.norm(ref))
        bar = dist(cyc[16][s][smp.texel])
        got, centre_only = dist(rows[s]), dist(one[s])
        msg = (f"{sun}: footprint {got:.4f} ({got / bar:.2f}x), centre {centre_only:.4f} "
               f"({centre_only / bar:.1f}x), Cycles 16 spp {bar:.4f}")
        print(msg)
        assert got <= 1.25 * bar, msg
        assert centre_only > 2 * bar, msg


def test_sub_samples_kept_across_chunks_give_the_rows_a_fresh_set_up_gives(fresh_scene,
                                                                         monkeypatch):
    """The smooth sub-samples a chunk of directions prepares are kept for the next chunks
    (lt_addon/rays/footprint.py ``prepare``, segments dropped oldest first past
    ``PREPARED_ROWS``): the demo bumps at 64^2, 24 low suns in chunks of 6 with the rows kept,
    and with a cap so small that every chunk drops the last's, equal the same directions each
    baked with a footprint of its own, bit for bit."""
    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.rays import footprint as fpm
    from relightable_textures.lt_addon.rays.direct import direct_rows
    from relightable_textures.lt_addon.rays.engine import Occluder
    from relightable_textures.operators.base import ray_scene

    samples.build("bumps", fresh_scene, "demo")
    obj = bpy.data.objects["Bumps"]
    dirs = np.array([direction_from_az_el(15.0 * k, 3.0 + k % 5) for k in range(24)])
    with ray_scene.RenderGeometry(fresh_scene) as depsgraph:
        V, T, _ = ray_scene.casters(depsgraph)
        occluder = Occluder(V, T)

        def fresh():
            return ray_scene.receiver_points(obj, depsgraph, 64)[1]
        each = np.concatenate([direct_rows(occluder, fresh(), d[None]) for d in dirs])
        kept = fresh()
        chunks = np.concatenate([direct_rows(occluder, kept, dirs[a:a + 6])
                                 for a in range(0, 24, 6)])
        segs = len(kept.footprint._segs)
        monkeypatch.setattr(fpm, "PREPARED_ROWS", 16 * 600)
        small = fresh()
        capped = np.concatenate([direct_rows(occluder, small, dirs[a:a + 6])
                                 for a in range(0, 24, 6)])
    assert kept.footprint.refined > 0 and segs >= 2
    assert len(small.footprint._segs) < 4 or small.footprint._seg_rows <= 16 * 600
    np.testing.assert_array_equal(chunks, each)
    np.testing.assert_array_equal(capped, each)
