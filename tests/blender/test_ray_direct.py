"""Ray-traced direct transport against Cycles' own bake of the same hard sun (issue 32).

The reference is independent: Cycles bakes the DIFFUSE direct pass of a Sun lamp (strength 1,
angle 0, 1 sample: the texel centre) at tiny sizes; the rays come from lt_addon/rays. Both are
``cos * V / pi`` at the same points (the texel positions equal Cycles' POSITION bake), so where
the rules agree the two agree to float precision -- measured 0.0000 relative on the bumps at
every elevation. Tolerances name what differs and are set from measurement (2026-12-02):

* Suzanne (a smooth low-poly mesh, flipped normals at its eye corners): 0 at 48^2, one texel of
  4,096 off by 0.049 at 64^2 and 10 degrees (0.0097 relative) -- a ray grazing its own triangle's
  plane at the shadow terminator;
* the bumps at 16^2 (texel centres 0.001 texel from the quads' edges): 1 of 256 texels at one of
  24 directions off by 0.023;
* Cycles' 1-spp bake against its own 16-spp bake differs by 0.02-0.07 (DESIGN.md): the bar the
  issue sets ("within Cycles' own 1-spp noise").
"""

import numpy as np
import pytest

from relightable_textures import samples
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el

#: Cycles' rules (backfacing, the bump terminator term) differ between releases: run on 5.2 LTS too.
pytestmark = pytest.mark.version_sensitive

LIGHTS = ((37.0, 5.0), (37.0, 10.0), (161.0, 20.0), (283.0, 45.0), (59.0, 80.0))


def _cycles_and_rays(scene, objects, R):
    """Cycles' direct bake (per light, per object: covered texels) and the rays' rows."""
    from relightable_textures.lt_addon.rays.direct import direct_rows
    from relightable_textures.lt_addon.rays.engine import Occluder
    from relightable_textures.operators.base import ray_scene
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    dirs = np.array([direction_from_az_el(a, e) for a, e in LIGHTS])
    with EnvironmentBake(scene, objects, R, 1, 0, (8, 16), mode="irradiance", seed=0,
                         world_sampling="none", passes="direct") as session:
        cyc = [session.bake_sun_all(d, 1.0, 0.0) for d in dirs]
        normals = None
        if any(ray_scene.normal_mapped(o) for o in objects):
            from relightable_textures.operators.bakes.ray_direct import world_normals

            normals = [world_normals(o, n) for o, n in zip(objects, session.bake_normals())]
    with ray_scene.RenderGeometry(scene) as depsgraph:
        V, T, n = ray_scene.casters(depsgraph)
        occluder = Occluder(V, T)
        # the texel centres alone: the rules of Cycles' first sample, exactly (the footprint's
        # mean is compared with a converged bake in test_footprint.py)
        pts = [ray_scene.receiver_points(o, depsgraph, R, None if normals is None else normals[i],
                                         footprint=False)
               for i, o in enumerate(objects)]
    out = []
    for i, (smp, p) in enumerate(pts):
        rays = direct_rows(occluder, p, dirs)
        cycles = np.stack([c[i][..., 0].reshape(-1)[smp.texel] for c in cyc])
        out.append((cycles, rays))
    return out, n


def _rel(a, b):
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-12))


def test_bumps_rays_equal_cycles_at_every_elevation(fresh_scene):
    import bpy

    samples.build("bumps", fresh_scene, "test")
    ((cycles, rays),), _ = _cycles_and_rays(fresh_scene, [bpy.data.objects["Bumps"]], 32)
    assert cycles.max() > 0.2                       # lit, with cast shadows at the low suns
    assert (cycles[0] == 0).mean() > 0.05
    for s in range(len(LIGHTS)):
        assert np.abs(rays[s] - cycles[s]).max() < 1e-4, LIGHTS[s]


def test_smooth_low_poly_and_two_objects_shadowing_each_other(fresh_scene):
    import bpy

    samples.build("statue", fresh_scene, "test")
    objs = [bpy.data.objects["Statue"], bpy.data.objects["Ground"]]
    (statue, ground), n = _cycles_and_rays(fresh_scene, objs, 48)
    assert n == 2
    for s, (az, el) in enumerate(LIGHTS):
        c, r = statue
        assert _rel(r[s], c[s]) < 0.02, (el, _rel(r[s], c[s]))
        assert np.mean(np.abs(r[s] - c[s]) > 0.02) < 0.005, el
        c, r = ground                                # Suzanne's shadow on the ground
        assert _rel(r[s], c[s]) < 0.03, (el, _rel(r[s], c[s]))
    # the statue's cast shadow is in the ground's texture at the lowest sun
    assert (ground[0][0] == 0).mean() > 0.01


def _plane(name, size, z=0.0, subdivisions=8, material=None):
    import bpy

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=subdivisions, y_subdivisions=subdivisions,
                                    size=size, location=(0, 0, z), calc_uvs=True)
    obj = bpy.context.active_object
    obj.name = name
    if material is not None:
        obj.data.materials.append(material)
    return obj


def test_normal_mapped_material(fresh_scene):
    """A normal-mapped floor (a tangent-space normal map image -> Normal Map -> Diffuse BSDF)
    under a cube: rays take the closure normal from Cycles' NORMAL bake, with the bump
    shadowing term where it differs from the smooth normal."""
    import bpy

    from relightable_textures.samples.scene_setup import diffuse_material
    from relightable_textures.operators.base.ray_scene import normal_mapped

    mat = diffuse_material("Mapped", (0.8, 0.8, 0.8))
    tree = mat.node_tree
    img = bpy.data.images.new("NormalMap", 64, 64, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    yy, xx = np.mgrid[0:64, 0:64] / 64.0
    nx, ny = 0.5 * np.sin(8 * np.pi * xx), 0.5 * np.cos(6 * np.pi * yy)
    px = np.ones((64, 64, 4))
    px[..., 0], px[..., 1] = nx * 0.5 + 0.5, ny * 0.5 + 0.5
    px[..., 2] = np.sqrt(np.maximum(1 - nx ** 2 - ny ** 2, 0)) * 0.5 + 0.5
    img.pixels.foreach_set(px.astype(np.float32).ravel())
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Linear"
    nmap = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(tex.outputs["Color"], nmap.inputs["Color"])
    tree.links.new(nmap.outputs["Normal"], tree.nodes["Diffuse BSDF"].inputs["Normal"])
    floor = _plane("Floor", 4.0, material=mat)
    bpy.ops.mesh.primitive_cube_add(size=0.8, location=(0.3, 0.2, 0.6))
    assert normal_mapped(floor) and not normal_mapped(bpy.context.active_object)
    ((cycles, rays),), _ = _cycles_and_rays(fresh_scene, [floor], 48)
    for s, (az, el) in enumerate(LIGHTS):
        assert _rel(rays[s], cycles[s]) < 0.02, (el, _rel(rays[s], cycles[s]))
    # the map matters: the floor's lit texels vary by far more than the smooth normal would give
    lit = cycles[3][cycles[3] > 0]
    assert np.std(lit) / np.mean(lit) > 0.1


def test_instanced_caster_casts_its_shadow(fresh_scene):
    """A collection instance (an empty instancing a collection holding a cube) shadows a floor:
    the depsgraph's instances are casters."""
    import bpy

    floor = _plane("Floor", 4.0, material=bpy.data.materials.new("M"))
    coll = bpy.data.collections.new("Props")
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(0, 0, 0))
    cube = bpy.context.active_object
    for c in list(cube.users_collection):
        c.objects.unlink(cube)
    coll.objects.link(cube)                       # not in the scene itself: only instanced
    for x in (-0.8, 0.8):
        inst = bpy.data.objects.new(f"Inst{x}", None)
        inst.instance_type = "COLLECTION"
        inst.instance_collection = coll
        inst.location = (x, 0.3, 0.5)
        fresh_scene.collection.objects.link(inst)
    ((cycles, rays),), n = _cycles_and_rays(fresh_scene, [floor], 48)
    assert n == 3                                  # the floor and two instances
    for s, (az, el) in enumerate(LIGHTS):
        assert np.abs(rays[s] - cycles[s]).max() < 1e-4, el
    assert (cycles[2] == 0).mean() > 0.02          # the instances' shadows are there


def test_alpha_masked_caster_is_baked_by_cycles(fresh_scene):
    import bpy

    from relightable_textures.lt_addon.errors import InputError
    from relightable_textures.operators.bakes import ray_direct
    from relightable_textures.operators.bakes.texture_transport import TransportTextureSettings

    floor = _plane("Floor", 4.0, material=bpy.data.materials.new("M"))
    leaf = bpy.data.materials.new("Leaf")
    leaf.use_nodes = True
    leaf.node_tree.nodes["Principled BSDF"].inputs["Alpha"].default_value = 0.3
    _plane("Leaves", 1.0, z=1.0, subdivisions=2, material=leaf)
    auto = ray_direct.choose(fresh_scene, [floor], TransportTextureSettings(direct="auto"))
    assert auto["engine"] == "cycles" and "Leaves" in auto["why"] and "alpha" in auto["why"]
    with pytest.raises(InputError, match="--direct rays cannot reproduce.*Leaves"):
        ray_direct.choose(fresh_scene, [floor], TransportTextureSettings(direct="rays"))
    leaf.node_tree.nodes["Principled BSDF"].inputs["Alpha"].default_value = 1.0
    assert ray_direct.choose(fresh_scene, [floor],
                             TransportTextureSettings(direct="auto"))["engine"] == "rays"


@pytest.mark.parametrize("scene_name,objects", [("bumps", ["Bumps"]),
                                                ("statue", ["Statue", "Ground"])])
def test_texture_bake_by_rays_equals_the_cycles_bake(fresh_scene, tmp_path, scene_name, objects):
    """The whole texture bake: T by rays and T by Cycles calls agree on every texel (in the
    store's half floats), margins included (both Blender's Extend margin), and the result says
    which engine baked."""
    import bpy

    from relightable_textures.operators.bakes.texture_transport import (
        TransportTextureSettings, bake_transport_textures)

    samples.build(scene_name, fresh_scene, "test")
    objs = [bpy.data.objects[o] for o in objects]
    T = {}
    for direct in ("rays", "cycles"):
        s = TransportTextureSettings(directions="hemi:24:1.5", resolution=16, bounces=0,
                                     model="none", direct=direct, texel_sampling="centre")
        gen = bake_transport_textures(fresh_scene, objs, s, str(tmp_path / direct),
                                      resume=False)
        try:
            while True:
                next(gen)
        except StopIteration as stop:
            res = stop.value
        assert res.direct["engine"] == direct
        T[direct] = np.concatenate([np.asarray(b.store.array, np.float32) for b in res.objects],
                                   axis=1)
        for b in res.objects:
            b.store.abort()
    from relightable_textures.lt_addon.rays.texels import texel_samples
    from relightable_textures.operators.base.meshes import uv_triangles

    covered = np.concatenate([texel_samples(uv_triangles(o), 16).texel + i * 256
                              for i, o in enumerate(objs)])
    d = np.abs(T["rays"] - T["cycles"])
    dc = d[:, covered]                               # the texels the bake samples
    assert np.mean(dc < 2e-3) > 0.998 and dc.max() < 0.05, (np.mean(dc < 2e-3), dc.max())
    if bpy.app.version < (5, 3, 0):
        # and the margin: Blender 4.2-5.2's Extend margin, which the ray bake applies too
        # (5.3's bake margin leaves more texels empty: measured on the statue at 16^2, 40
        # margin texels at 0 against 19 -- not reproduced, so not compared there)
        assert np.mean(d < 2e-3) > 0.998 and d.max() < 0.05, (np.mean(d < 2e-3), d.max())
    assert res.direct["engine"] == "cycles"
    assert T["rays"].max() > 0.2


def test_render_settings_decide_the_geometry(fresh_scene):
    """Rays see what Cycles renders, not what the viewport shows: a caster hidden in the
    viewport but rendered casts its shadow, one that does not render casts none, and a
    subdivision modifier counts at its render levels (all restored afterwards)."""
    import bpy

    from relightable_textures.operators.base import ray_scene

    _plane("Floor", 4.0, material=bpy.data.materials.new("M"))
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0, 0, 1))
    shown = bpy.context.active_object
    shown.hide_viewport = True                       # renders: a caster
    sub = shown.modifiers.new("Sub", "SUBSURF")
    sub.levels, sub.render_levels = 0, 2
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(1, 1, 1))
    gone = bpy.context.active_object
    gone.hide_render = True                          # does not render: no shadow
    with ray_scene.RenderGeometry(fresh_scene) as depsgraph:
        V, T, n = ray_scene.casters(depsgraph)
        _, T_rest, n_rest = ray_scene.casters(depsgraph, exclude_names=[shown.name])
    assert n == 2                                    # the floor and the subdivided cube
    assert len(T) == 2 * 8 * 8 + 12 * 16             # 8x8 grid, the cube at 2 render levels
    assert n_rest == 1 and len(T_rest) == 2 * 8 * 8  # a named object left to its caller
    assert shown.hide_viewport and sub.levels == 0 and gone.hide_render   # restored


def test_a_ray_budget_splits_the_directions_and_changes_no_bit(fresh_scene, tmp_path,
                                                                 monkeypatch):
    """The engine calls hold at most RAY_BUDGET rays (the 1024^2 statue held 4.1 GB in one
    call of 64 directions): a budget of 5 directions' rays (24 directions in 5 calls, the last
    short) bakes the same T bit for bit as one call of all 24, and says so in its figures."""
    import bpy

    from relightable_textures.operators.bakes import ray_direct
    from relightable_textures.operators.bakes.texture_transport import (
        TransportTextureSettings, bake_transport_textures)
    from relightable_textures.operators.base.jobs import run

    samples.build("statue", fresh_scene, "test")
    objs = [bpy.data.objects["Statue"], bpy.data.objects["Ground"]]
    s = TransportTextureSettings(directions="hemi:24:1.5", resolution=16, bounces=0,
                                 model="none", direct="rays")
    T, calls = {}, {}
    for name, budget in (("one call", ray_direct.RAY_BUDGET), ("budget", None)):
        if budget is None:   # 5 directions of the largest receiver's texels per call
            from relightable_textures.lt_addon.rays.texels import texel_samples
            from relightable_textures.operators.base.meshes import uv_triangles

            most = max(texel_samples(uv_triangles(o), 16).size for o in objs)
            monkeypatch.setattr(ray_direct, "RAY_BUDGET", 5 * most + most // 2)
        res = run(bake_transport_textures(fresh_scene, objs, s, str(tmp_path / name),
                                               resume=False))
        T[name] = [np.asarray(b.store.array).copy() for b in res.objects]
        calls[name] = res.direct["directions_per_call"]
        for b in res.objects:
            b.store.abort()
    assert calls == {"one call": ray_direct.RAY_CHUNK, "budget": 5}
    for a, b in zip(T["one call"], T["budget"]):
        assert a.shape == b.shape and np.array_equal(a, b)
    assert max(float(t.max()) for t in T["budget"]) > 0.2
