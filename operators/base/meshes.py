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
    """UV coordinates of the mesh's triangulated faces (the bake's UV map, :func:`bake_uv_name`),
    shape (T, 3, 2)."""
    mesh = obj.data
    mesh.calc_loop_triangles()
    loops = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("loops", loops)
    return uv_corners(mesh, bake_uv_name(obj))[loops].reshape(-1, 3, 2)


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


#: The UV map a bake uses when the user chose one (``--uv-map NAME``, the panel's UV Map), for
#: every object of the bake; None: each mesh's active UV map (:func:`bake_uv_name`).
_UV_MAP_CHOICE: list = [None]


class chosen_uv_map:
    """Context manager: bakes inside it use the UV map named ``name`` on every object (None or
    "" leaves the default, the active map); an object without it is refused in one line
    (:func:`bake_uv_name`)."""

    def __init__(self, name: str | None):
        self.name = name or None

    def __enter__(self):
        self._old = _UV_MAP_CHOICE[0]
        _UV_MAP_CHOICE[0] = self.name
        return self

    def __exit__(self, *exc):
        _UV_MAP_CHOICE[0] = self._old
        return False


def uv_map_choice() -> str | None:
    """The UV map the user chose for this bake (:class:`chosen_uv_map`), or None."""
    return _UV_MAP_CHOICE[0]


def bake_uv_name(obj_or_mesh, choice: str | None = None) -> str:
    """The one UV map every stage of a bake of this object uses -- the rays' texels, Cycles'
    bakes (albedo, truths, normals: given as ``uv_layer``), the indirect term, the previews'
    UV Map nodes and the exports: the map chosen (``choice``, else :func:`uv_map_choice`),
    else the mesh's *active* UV map, which is the one Cycles' bake writes into when it is
    given no ``uv_layer`` (``RE_bake_pixels_populate`` in source/blender/render/intern/bake.cc:
    ``CustomData_get_layer(..., CD_PROP_FLOAT2)``, the active layer, in 4.x;
    ``mesh->active_uv_map_name()`` in 5.x; confirmed with bpy 5.0.1 by baking a plane with two
    maps) -- not the map marked for rendering (``active_render``). Raises the bake's input
    error in one line when the chosen map does not exist or the mesh has no UV map."""
    from ...lt_addon.errors import InputError

    mesh = obj_or_mesh.data if isinstance(obj_or_mesh, bpy.types.Object) else obj_or_mesh
    owner = obj_or_mesh.name
    choice = choice or uv_map_choice()
    if not mesh.uv_layers:
        raise InputError(f"{owner} has no UV map; add one (UV > Unwrap) before baking")
    if choice:
        if choice not in mesh.uv_layers:
            have = ", ".join(repr(u.name) for u in mesh.uv_layers)
            raise InputError(f"{owner} has no UV map named {choice!r} (it has {have}); choose "
                             "one of them or leave the UV map unset (the active one)")
        return choice
    active = mesh.uv_layers.active
    return (active if active is not None else mesh.uv_layers[0]).name


def baked_uv_name(obj, report: dict | None = None) -> str:
    """The UV map a finished bake of ``obj`` was baked into, for what reads its textures (the
    previews' UV Map nodes, the exports): the report's ``uv_map`` where the mesh still has it,
    else the rule of :func:`bake_uv_name` (reports written before it was recorded)."""
    name = (report or {}).get("uv_map")
    if name and name in obj.data.uv_layers:
        return name
    from ...lt_addon.errors import InputError

    try:
        return bake_uv_name(obj)
    except InputError:   # a choice (of a later bake) this object lacks: its active map
        layers = obj.data.uv_layers
        return (layers.active or layers[0]).name


def uv_corners(mesh, layer=None) -> np.ndarray:
    """UVs per face corner of ``layer`` (a UV layer or its name; default: the bake's map,
    :func:`bake_uv_name`), shape (L, 2)."""
    if layer is None or isinstance(layer, str):
        layer = mesh.uv_layers[layer or bake_uv_name(mesh)]
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
