"""The one place where arrays become Blender meshes and back (bpy).

Keep bpy read/write helpers here so the rest of the bpy layer speaks arrays.
"""

from __future__ import annotations

import bpy
import numpy as np


def grid_faces(rows: int, cols: int) -> np.ndarray:
    """Quad indices of a ``rows x cols`` vertex grid stored row-major.

    Returns
    -------
    faces : ndarray, shape ((rows - 1) * (cols - 1), 4), int64
        Counter-clockwise (seen from +z when rows run along +y and cols along +x).
    """
    idx = np.arange(rows * cols).reshape(rows, cols)
    a = idx[:-1, :-1].ravel()
    b = idx[:-1, 1:].ravel()
    c = idx[1:, 1:].ravel()
    d = idx[1:, :-1].ravel()
    return np.stack([a, b, c, d], axis=1)


def mesh_object(name: str, vertices: np.ndarray, faces: np.ndarray, collection,
                uv: np.ndarray | None = None, smooth: bool = True):
    """Create a mesh object from arrays and link it into ``collection``.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
        Object-space positions (metres).
    faces : ndarray, shape (F, K), int
        Polygon vertex indices, all polygons with K corners.
    uv : ndarray, shape (V, 2), optional
        Per-vertex UV coordinates; written per corner into a UV map named ``UVMap``.
    smooth : bool
        Smooth shading (interpolated normals), which bakes want for curved height fields.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(vertices.tolist(), [], faces.tolist())
    if uv is not None:
        layer = mesh.uv_layers.new(name="UVMap")
        corner_vertex = np.empty(len(mesh.loops), dtype=np.int64)
        mesh.loops.foreach_get("vertex_index", corner_vertex)
        layer.data.foreach_set("uv", np.asarray(uv, dtype=np.float32)[corner_vertex].ravel())
    return _link_object(name, mesh, collection, smooth)


def _link_object(name: str, mesh, collection, smooth: bool):
    mesh.shade_smooth() if smooth else mesh.shade_flat()
    mesh.validate()
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    return obj


def vertex_positions(obj) -> np.ndarray:
    """Object-space vertex positions of a mesh object or datablock, shape (V, 3), float64."""
    mesh = obj.data if isinstance(obj, bpy.types.Object) else obj
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def world_bounds(obj) -> np.ndarray:
    """Axis-aligned world-space bounds of a mesh object, shape (2, 3): [min, max] in metres."""
    co = vertex_positions(obj)
    m = np.array(obj.matrix_world, dtype=np.float64)
    world = co @ m[:3, :3].T + m[:3, 3]
    return np.stack([world.min(axis=0), world.max(axis=0)])


def object_from_bmesh(name: str, bm, collection, smooth: bool = True):
    """Write a BMesh into a new mesh object linked into ``collection``; frees ``bm``."""
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    return _link_object(name, mesh, collection, smooth)


def uv_triangles(obj) -> np.ndarray:
    """UV coordinates of the mesh's triangulated faces (active render UV map), shape (T, 3, 2)."""
    mesh = obj.data
    mesh.calc_loop_triangles()
    loops = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("loops", loops)
    return uv_corners(mesh)[loops].reshape(-1, 3, 2)


def mesh_edges(obj) -> np.ndarray:
    """The base mesh's edges as vertex index pairs, shape (E, 2), int64."""
    e = np.empty(len(obj.data.edges) * 2, dtype=np.int64)
    obj.data.edges.foreach_get("vertices", e)
    return e.reshape(-1, 2)


def vertex_normals(mesh) -> np.ndarray:
    """Object-space vertex normals of a mesh datablock, shape (V, 3), float64 (unit)."""
    n = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
    mesh.vertices.foreach_get("normal", n)
    return n.reshape(-1, 3)


def corner_vertices(mesh) -> np.ndarray:
    """The vertex of every face corner (loop), shape (L,), int64."""
    v = np.empty(len(mesh.loops), dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", v)
    return v


def polygon_arrays(mesh) -> tuple:
    """Per face: area (m^2 in object space), first corner and corner count; each shape (F,)."""
    f = len(mesh.polygons)
    area, start, total = (np.empty(f, np.float64), np.empty(f, np.int64), np.empty(f, np.int64))
    mesh.polygons.foreach_get("area", area)
    mesh.polygons.foreach_get("loop_start", start)
    mesh.polygons.foreach_get("loop_total", total)
    return area, start, total


def uv_corners(mesh, layer=None) -> np.ndarray:
    """UVs per face corner of ``layer`` (default: the active render map), shape (L, 2)."""
    layer = layer or next((uv for uv in mesh.uv_layers if uv.active_render), mesh.uv_layers[0])
    uv = np.empty(len(mesh.loops) * 2, dtype=np.float64)
    layer.data.foreach_get("uv", uv)
    return uv.reshape(-1, 2)


def set_uv_corners(layer, uv) -> None:
    """Write (L, 2) UVs into a UV layer."""
    layer.data.foreach_set("uv", np.asarray(uv, np.float32).ravel())


def color_attribute(attr) -> np.ndarray:
    """RGBA of a colour attribute (any domain), shape (N, 4), float32 (linear)."""
    px = np.empty(len(attr.data) * 4, dtype=np.float32)
    attr.data.foreach_get("color", px)
    return px.reshape(-1, 4)


def set_color_attribute(attr, rgb) -> None:
    """Write (N, 3) linear RGB (alpha 1) into a colour attribute."""
    rgba = np.ones((len(attr.data), 4), dtype=np.float32)
    rgba[:, :3] = rgb
    attr.data.foreach_set("color", rgba.ravel())


def image_pixels(img) -> np.ndarray:
    """An image's pixels, shape (H, W, channels), float32, bottom row first (Blender order)."""
    w, h = img.size
    px = np.empty(w * h * img.channels, dtype=np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, img.channels)


def set_image_pixels(img, rgb) -> None:
    """Write (H, W, 3) or (H, W) linear values (alpha 1) into an RGBA image, bottom row first."""
    rgb = np.asarray(rgb, np.float32)
    w, h = img.size
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = rgb[..., None] if rgb.ndim == 2 else rgb
    img.pixels.foreach_set(rgba.ravel())
