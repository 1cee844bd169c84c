"""The paper's tileable patches: ``bumps`` (bumps and dents) and ``noise`` (Perlin height field).

Real geometry, not displacement: the height field is sampled on a regular vertex grid, so
Cycles bakes see true shadows and interreflection and the vertex count is exact. The patch is
2 m x 2 m centred on the origin with UVs spanning [0, 1]^2; heights are in metres.
"""

from __future__ import annotations

import numpy as np

from ..lt_addon.geometry import heightfield
from ..operators.base.meshes import grid_faces, mesh_object
from . import scene_setup

#: Grid quads per side, by size.
RESOLUTION = {"test": 32, "demo": 128}
PATCH_SIZE = 2.0


def _patch(scene, size: str, name: str, heights) -> dict:
    res = RESOLUTION[size]
    u, v = heightfield.grid(res)
    z = heights(u, v) * PATCH_SIZE
    verts = np.stack([(u - 0.5) * PATCH_SIZE, (v - 0.5) * PATCH_SIZE, z], axis=-1).reshape(-1, 3)
    uv = np.stack([u, v], axis=-1).reshape(-1, 2)
    faces = grid_faces(res + 1, res + 1)
    scene_setup.configure_cycles(scene, size)
    scene_setup.uniform_world(scene, f"{name}World", strength=1.0)
    coll = scene.collection
    obj = mesh_object(name, verts, faces, coll, uv=uv, smooth=True)
    obj.data.materials.append(scene_setup.diffuse_material(f"{name}Material", (0.8, 0.8, 0.8)))
    scene_setup.ortho_top_camera(scene, coll, (0.0, 0.0), PATCH_SIZE)
    scene_setup.sun_lamp(coll)
    return {"relight_object": obj.name, "frame": "tangent"}


def build_bumps(scene, size: str) -> dict:
    """Bumps and dents: a 4 x 4 checkerboard of spherical caps (Ashikhmin & Shirley Fig. 5)."""
    return _patch(scene, size, "Bumps",
                  lambda u, v: heightfield.bumps_and_dents(u, v, cells=4, radius=0.35, depth=0.8))


def build_noise(scene, size: str) -> dict:
    """A Perlin-noise height field with period 1 (seed 0), three octaves."""
    return _patch(scene, size, "Noise",
                  lambda u, v: heightfield.perlin_noise(u, v, period=4, octaves=3, amplitude=0.06))
