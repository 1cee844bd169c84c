"""Object scenes: ``statue`` (self-shadowing object on a ground plane) and ``room`` (colour bleeding).

Built with bmesh primitives and explicit subdivision so vertex counts are exact and the same on
every run. Every mesh has a UV map (primitive UVs; the ground and walls are planar grids).
"""

from __future__ import annotations

import math

import bmesh
import numpy as np
from mathutils import Matrix

from ..operators.base.meshes import grid_faces, mesh_object, object_from_bmesh
from . import scene_setup

#: (object subdivision cuts, ground / wall grid quads per side), by size.
DETAIL = {"test": (0, 8), "demo": (2, 32)}


def _plane(name: str, collection, side: float, quads: int, matrix: Matrix, material):
    """A subdivided square of ``side`` metres in its local xy plane, placed by ``matrix``."""
    t = np.linspace(0.0, 1.0, quads + 1)
    v, u = np.meshgrid(t, t, indexing="ij")
    verts = np.stack([(u - 0.5) * side, (v - 0.5) * side, np.zeros_like(u)], axis=-1).reshape(-1, 3)
    uv = np.stack([u, v], axis=-1).reshape(-1, 2)
    obj = mesh_object(name, verts, grid_faces(quads + 1, quads + 1), collection, uv=uv, smooth=False)
    obj.matrix_world = matrix
    obj.data.materials.append(material)
    return obj


def _primitive(name: str, collection, make, cuts: int, material, matrix: Matrix, smooth=True):
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    make(bm)
    if cuts:
        bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=cuts, use_grid_fill=True)
    obj = object_from_bmesh(name, bm, collection, smooth=smooth)
    obj.matrix_world = matrix
    obj.data.materials.append(material)
    return obj


def build_statue(scene, size: str) -> dict:
    """Suzanne (strong self-shadowing: ears, brow, eye sockets) standing on a 6 m ground plane."""
    cuts, quads = DETAIL[size]
    coll = scene.collection
    scene_setup.configure_cycles(scene, size)
    scene_setup.sky_world(scene, "StatueWorld")
    white = scene_setup.diffuse_material("StatueMaterial", (0.8, 0.8, 0.8))
    ground_mat = scene_setup.diffuse_material("GroundMaterial", (0.5, 0.5, 0.5))
    # Suzanne spans z in about [-0.98, 0.98] once stood up; lift it onto the ground.
    upright = Matrix.Translation((0.0, 0.0, 1.0)) @ Matrix.Rotation(math.radians(-20.0), 4, "Z")
    statue = _primitive("Statue", coll, lambda bm: bmesh.ops.create_monkey(bm, calc_uvs=True),
                        cuts, white, upright)
    _plane("Ground", coll, 6.0, quads, Matrix.Identity(4), ground_mat)
    scene_setup.perspective_camera(scene, coll, (0.0, -6.0, 3.0), (0.0, 0.0, 0.9))
    scene_setup.sun_lamp(coll)
    return {"relight_object": statue.name, "frame": "world"}


def build_room(scene, size: str, quads: int | None = None) -> dict:
    """A 2 m open box (no ceiling, open front): grey floor, red left, green right and white back
    wall, with a cube inside, so diffuse interreflection bleeds colour across the surfaces.
    ``quads``: grid quads per side of the floor and walls instead of the size's (the bench
    times updates on a 13K-vertex room)."""
    cuts, size_quads = DETAIL[size]
    quads = size_quads if quads is None else int(quads)
    coll = scene.collection
    scene_setup.configure_cycles(scene, size)
    scene_setup.sky_world(scene, "RoomWorld", sun_az_el=(250.0, 40.0))
    mats = {
        "Floor": scene_setup.diffuse_material("FloorMaterial", (0.7, 0.7, 0.7)),
        "WallLeft": scene_setup.diffuse_material("RedMaterial", (0.8, 0.1, 0.1)),
        "WallRight": scene_setup.diffuse_material("GreenMaterial", (0.1, 0.8, 0.1)),
        "WallBack": scene_setup.diffuse_material("WhiteMaterial", (0.8, 0.8, 0.8)),
    }
    T, R = Matrix.Translation, Matrix.Rotation
    placement = {
        "Floor": Matrix.Identity(4),
        "WallLeft": T((-1.0, 0.0, 1.0)) @ R(math.radians(90.0), 4, "Y"),
        "WallRight": T((1.0, 0.0, 1.0)) @ R(math.radians(-90.0), 4, "Y"),
        "WallBack": T((0.0, 1.0, 1.0)) @ R(math.radians(90.0), 4, "X"),
    }
    for name, matrix in placement.items():
        _plane(name, coll, 2.0, quads, matrix, mats[name])
    box_mat = scene_setup.diffuse_material("BoxMaterial", (0.8, 0.8, 0.6))
    box_matrix = T((0.1, 0.2, 0.35)) @ R(math.radians(25.0), 4, "Z")
    box = _primitive("Box", coll, lambda bm: bmesh.ops.create_cube(bm, size=0.7, calc_uvs=True),
                     cuts + 1, box_mat, box_matrix, smooth=False)
    scene_setup.perspective_camera(scene, coll, (0.0, -4.5, 1.6), (0.0, 0.2, 0.8))
    scene_setup.sun_lamp(coll)
    return {"relight_object": box.name, "frame": "world"}
