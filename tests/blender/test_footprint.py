"""Each texel's footprint against a converged Cycles bake (issue 55).

A 1-spp Cycles bake -- and the ray bake with one ray per texel -- samples the texel centre; every
further Cycles sample jitters the point over half a texel inside the centre's triangle
(lt_addon/rays/footprint.py). Where a shadow edge or a thin triangle passes a texel the two
differ, and a grazing sun on relief is made of such texels. The reference here is Cycles' own
256-spp bake of the same hard sun (the DIFFUSE direct pass, irradiance: cos x V / pi); the bar
is Cycles' own 16-spp bake's distance from it, per direction (the issue's: within 1.25x).

The scene: a flat-shaded brick relief (a 65 x 65 vertex grid over 2 m, bricks 0.25 x 0.125 m
raised 0.1 m over 3 cm mortar grooves, planar UVs), 64^2. Measured 2026-12-06 (bpy 5.0.1):
see the asserts' messages for the figures of a run.
"""

import numpy as np
import pytest

from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el

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
