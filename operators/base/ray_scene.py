"""The scene as arrays for the ray engine (bpy): shadow casters, receivers' shading points, and what
rays cannot reproduce.

The geometry is read from the evaluated depsgraph -- modifiers, instances (collection instances,
instancing by vertices and faces, geometry nodes), curves and text -- with the modifiers' render
settings and render visibility, as Cycles bakes it: for the read the viewport settings of every
modifier and object are set to their render settings and restored (:class:`RenderGeometry`).
The core of :mod:`...lt_addon.rays` does the rest.
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from ...lt_addon.rays.shading import shading_points
from ...lt_addon.rays.texels import texel_samples
from .meshes import bake_uv_name, uv_corners

#: Object types whose evaluated geometry Blender can triangulate (to_mesh).
CASTER_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}
#: The first Blender whose Cycles has the Conty Estevez bump terminator term (4.5.15 has it,
#: 4.2.13 has Chiang et al.'s; 4.3-4.4 are assumed to be as 4.5, not checked).
BUMP_CONTY_FROM = (4, 5, 0)
#: Object types rays do not reproduce: their shadows need Cycles.
UNSUPPORTED_TYPES = {"CURVES": "hair curves", "POINTCLOUD": "a point cloud", "VOLUME": "a volume"}


class RenderGeometry:
    """Context manager: the depsgraph evaluated with every modifier's, object's and collection's
    render settings (subdivision levels, show_viewport, hide_viewport), restored on exit. Yields
    the evaluated depsgraph."""

    def __init__(self, scene):
        self.scene = scene
        self._restore = []

    def _set(self, owner, name, value):
        old = getattr(owner, name)
        if old != value:
            self._restore.append((owner, name, old))
            setattr(owner, name, value)

    def __enter__(self):
        view_layer = bpy.context.view_layer
        for coll in self.scene.collection.children_recursive:   # what renders, as a collection
            self._set(coll, "hide_viewport", coll.hide_render)
        for o in self.scene.objects:
            self._set(o, "hide_viewport", o.hide_render)
            if not o.hide_render and o.hide_get(view_layer=view_layer):
                o.hide_set(False)
                self._restore.append((o, "hide_set", True))
            for m in getattr(o, "modifiers", ()):
                self._set(m, "show_viewport", m.show_render)
                if m.type in ("SUBSURF", "MULTIRES"):      # viewport levels = render levels
                    self._set(m, "levels", m.render_levels)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        depsgraph.update()
        return depsgraph

    def __exit__(self, *exc):
        for owner, name, old in reversed(self._restore):
            if name == "hide_set":
                owner.hide_set(old)
            else:
                setattr(owner, name, old)
        self._restore.clear()
        bpy.context.evaluated_depsgraph_get().update()
        return False


@dataclass
class MeshArrays:
    """An evaluated mesh in world space, as the ray bakes read it (:func:`mesh_arrays`).

    co (V, 3) vertices;  tri, loops (T, 3) each loop triangle's vertices and face corners;
    poly (T,) its face;  smooth, mat_index (F,) per face;  corner_vertex (C,);  corner_normals
    (C, 3) unit, world ((M^-1)^T n: a zero scale is not an error);  face_centre (F, 3);
    loop_start, loop_total (F,);  uv (C, 2) the bake's UV map (:func:`.meshes.bake_uv_name`;
    None without one);
    matrix (4, 4) the object's world matrix.
    """

    co: np.ndarray
    tri: np.ndarray
    loops: np.ndarray
    poly: np.ndarray
    smooth: np.ndarray
    mat_index: np.ndarray
    corner_vertex: np.ndarray
    corner_normals: np.ndarray
    face_centre: np.ndarray
    loop_start: np.ndarray
    loop_total: np.ndarray
    uv: np.ndarray
    matrix: np.ndarray

    @property
    def mirrored(self) -> bool:
        """The transform flips orientation (Cycles flips the geometric normal)."""
        return bool(np.linalg.det(self.matrix[:3, :3]) < 0)


def _uv_name_or_none(obj):
    """The bake's UV map of ``obj`` (:func:`.meshes.bake_uv_name`), or None where it has none
    (an object read only as a caster or per vertex; a receiver was refused before)."""
    from ...lt_addon.errors import InputError

    if obj.type != "MESH" or not obj.data.uv_layers:
        return None
    try:
        return bake_uv_name(obj)
    except InputError:
        return None


def mesh_arrays(obj, depsgraph) -> MeshArrays:
    """The evaluated mesh of ``obj`` (its render geometry within :class:`RenderGeometry`) as
    :class:`MeshArrays`: the one reader of the texture bake's texels, the vertex bake's points,
    the live preview's rays and the gathered bounces."""
    uv_name = _uv_name_or_none(obj)
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        M = np.array(obj.matrix_world, np.float64)
        co = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
        co = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
        mesh.calc_loop_triangles()
        T = len(mesh.loop_triangles)
        tri, loops = np.empty(T * 3, np.int64), np.empty(T * 3, np.int64)
        poly = np.empty(T, np.int64)
        mesh.loop_triangles.foreach_get("vertices", tri)
        mesh.loop_triangles.foreach_get("loops", loops)
        mesh.loop_triangles.foreach_get("polygon_index", poly)
        F = len(mesh.polygons)
        smooth, mat_index = np.empty(F, bool), np.empty(F, np.int64)
        mesh.polygons.foreach_get("use_smooth", smooth)
        mesh.polygons.foreach_get("material_index", mat_index)
        centre = np.empty(F * 3)
        mesh.polygons.foreach_get("center", centre)
        start, total = np.empty(F, np.int64), np.empty(F, np.int64)
        mesh.polygons.foreach_get("loop_start", start)
        mesh.polygons.foreach_get("loop_total", total)
        corner_v = np.empty(len(mesh.loops), np.int64)
        mesh.loops.foreach_get("vertex_index", corner_v)
        cn = np.empty(len(mesh.loops) * 3)
        mesh.corner_normals.foreach_get("vector", cn)
        cn = cn.reshape(-1, 3) @ np.linalg.pinv(M[:3, :3])     # (M^-T n), as row vectors
        cn /= np.maximum(np.linalg.norm(cn, axis=1, keepdims=True), 1e-30)
        uv = (uv_corners(mesh, uv_name) if uv_name is not None and uv_name in mesh.uv_layers
              else None)
    finally:
        ev.to_mesh_clear()
    return MeshArrays(co, tri.reshape(-1, 3), loops.reshape(-1, 3), poly, smooth, mat_index,
                      corner_v, cn, centre.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3], start,
                      total, uv, M)


def _to_world_mesh(obj_eval, matrix):
    """World vertices (V, 3), loop triangles (T, 3) of an evaluated object (None if empty)."""
    mesh = obj_eval.to_mesh()
    try:
        if mesh is None or not len(mesh.vertices):
            return None
        co = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
        M = np.array(matrix, np.float64)
        co = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
        mesh.calc_loop_triangles()
        tri = np.empty(len(mesh.loop_triangles) * 3, np.int64)
        mesh.loop_triangles.foreach_get("vertices", tri)
        return co, tri.reshape(-1, 3)
    finally:
        obj_eval.to_mesh_clear()


def _caster_meshes(depsgraph, flag: str, exclude_names=()):
    """``(object name, world vertices, triangles)`` of every evaluated object and instance
    whose rays ``flag`` (``visible_shadow``, ``visible_diffuse``) meet, ``exclude_names`` left
    out: what :func:`casters` and :func:`with_contacts` read."""
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type not in CASTER_TYPES or ob.original.name in exclude_names:
            continue
        original = ob.original
        parent = inst.parent.original if inst.is_instance and inst.parent else None
        if not getattr(original, flag, True) or (
                parent is not None and not getattr(parent, flag, True)):
            continue
        got = _to_world_mesh(ob, inst.matrix_world)
        if got is not None:
            yield original.name, got[0], got[1]


def casters(depsgraph, exclude_names=(), ray: str = "shadow"):
    """World-space triangles of every object ``ray`` rays meet: (vertices (N, 3), triangles
    (T, 3), count of objects and instances). ``ray`` "shadow": the shadow casters (objects
    whose ``visible_shadow`` is off are left out, as Cycles leaves them out of shadow rays);
    "diffuse": what diffuse bounce rays meet (``visible_diffuse``; an object that casts no
    shadow still reflects light). The objects named in ``exclude_names`` are left out too (a
    caller that reads them itself). The depsgraph is :class:`RenderGeometry`'s: objects hidden
    from render, or in collections hidden from render or excluded, are not in it."""
    verts, tris, n, offset = [], [], 0, 0
    for _, co, tri in _caster_meshes(depsgraph, f"visible_{ray}", exclude_names):
        verts.append(co)
        tris.append(tri + offset)
        offset += len(co)
        n += 1
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), 0
    return np.concatenate(verts), np.concatenate(tris), n


def with_contacts(depsgraph, receivers, threads: int = 0):
    """Give each receiver's shading points (``receivers``: (object name, ShadingPoints)) the
    :class:`...lt_addon.rays.contact.Contact` of the other shadow casters' surfaces they touch
    (a box's bottom on its floor: :mod:`...lt_addon.rays.contact`), in place. The casters are
    read once; per receiver an occluder of the other objects' triangles near it is built only
    where some lie within its points' reach. Returns the touching points in all."""
    from ...lt_addon.rays import contact
    from ...lt_addon.rays.engine import Occluder

    receivers = [(n, p) for n, p in receivers if p.size]
    if not receivers:
        return 0
    verts, tris, owner, offset = [], [], [], 0
    for name, co, tri in _caster_meshes(depsgraph, "visible_shadow"):
        verts.append(co)
        tris.append(tri + offset)
        owner.append(np.full(len(tri), name, object))
        offset += len(co)
    if not verts:
        return 0
    V, T, owner = np.concatenate(verts), np.concatenate(tris), np.concatenate(owner)
    touching = 0
    for name, points in receivers:
        rows = contact.near_triangles(V, T, points.P.min(axis=0), points.P.max(axis=0),
                                      contact.reach(points))
        rows = rows[owner[rows] != name]
        if not len(rows):
            continue
        found = contact.find(points, Occluder(V, T[rows], threads=threads))
        points.contact = found
        touching += found.count if found is not None else 0
    return touching


def _material_trees(obj):
    for slot in getattr(obj, "material_slots", ()):
        mat = slot.material
        if mat is not None and mat.use_nodes and mat.node_tree is not None:
            yield mat, mat.node_tree


def _alpha_reason(mat, tree):
    for node in tree.nodes:
        if node.bl_idname in ("ShaderNodeBsdfTransparent", "ShaderNodeHoldout"):
            return f"material {mat.name!r} has a {node.bl_label} node (see-through shadows)"
        alpha = node.inputs.get("Alpha") if node.bl_idname == "ShaderNodeBsdfPrincipled" else None
        if alpha is not None and (alpha.is_linked or alpha.default_value < 1.0):
            return f"material {mat.name!r} has an alpha below 1 (see-through shadows)"
    return None


def _output_linked(tree, socket: str) -> bool:
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeOutputMaterial" and node.is_active_output:
            s = node.inputs.get(socket)
            return bool(s is not None and s.is_linked)
    return False


def _displacement_reason(mat, tree):
    method = getattr(mat, "displacement_method", None) or getattr(
        getattr(mat, "cycles", None), "displacement_method", "BUMP")
    if method in ("DISPLACEMENT", "BOTH") and _output_linked(tree, "Displacement"):
        return f"material {mat.name!r} uses true displacement"
    return None


def unsupported(scene, depsgraph, receivers) -> list:
    """Why rays cannot reproduce Cycles' direct light in this scene ([] when they can): hair,
    point clouds, volumes, see-through (alpha, transparent) shadow casters, true displacement,
    volume shaders."""
    why = []
    seen = set()
    for inst in depsgraph.object_instances:
        ob = inst.object.original
        if ob.name in seen:
            continue
        seen.add(ob.name)
        if ob.type in UNSUPPORTED_TYPES:
            if getattr(ob, "visible_shadow", True):
                why.append(f"{ob.name} is {UNSUPPORTED_TYPES[ob.type]}")
            continue
        if ob.type not in CASTER_TYPES:
            continue
        for ps in getattr(ob, "particle_systems", ()):
            if ps.settings.type == "HAIR" and ps.settings.render_type == "PATH":
                why.append(f"{ob.name} has hair particles")
        caster = getattr(ob, "visible_shadow", True)
        for mat, tree in _material_trees(ob):
            reason = _alpha_reason(mat, tree) if caster else None
            reason = reason or _displacement_reason(mat, tree)
            if reason is None and _output_linked(tree, "Volume"):
                reason = f"material {mat.name!r} has a volume shader"
            if reason:
                why.append(f"{ob.name}: {reason}")
    world = scene.world
    if world is not None and world.use_nodes and world.node_tree is not None:
        for node in world.node_tree.nodes:
            if node.bl_idname == "ShaderNodeOutputWorld" and node.inputs["Volume"].is_linked:
                why.append("the world has a volume shader")
    return sorted(set(why))


def normal_mapped(obj) -> bool:
    """Whether a material of ``obj`` changes the shading normal (a link into a BSDF's Normal
    input, or bump through the Displacement output)."""
    for mat, tree in _material_trees(obj):
        if _output_linked(tree, "Displacement"):
            return True
        for node in tree.nodes:
            s = node.inputs.get("Normal") if node.bl_idname.startswith("ShaderNodeBsdf") else None
            if s is not None and s.is_linked:
                return True
    return False


def receiver_points(obj, depsgraph, resolution: int, Ns_image=None, footprint: bool = True):
    """(TexelSamples, ShadingPoints) of ``obj``'s texture bake at ``resolution``: the evaluated
    mesh in world space, its bake UV map (:func:`.meshes.bake_uv_name`), corner normals, smooth
    flags and the object's shadow-terminator geometry offset. ``Ns_image``: for normal-mapped
    materials, (R, R, 3) world closure normals (a Cycles normal bake) or a
    :class:`...lt_addon.rays.normal_samples.TexelNormals` (their mean, and each texel's sampled
    normals where they vary); else None. ``footprint``: the points carry their texels'
    :class:`...lt_addon.rays.footprint.Footprint` (rays where a shadow edge passes average the
    texel as a converged Cycles bake does)."""
    m = mesh_arrays(obj, depsgraph)
    if m.uv is None:
        raise ValueError(f"{obj.name} has no UV map")
    tri, loops, poly, mat_index = m.tri, m.loops.ravel(), m.poly, m.mat_index
    cn = m.corner_normals
    uv = m.uv[loops].reshape(-1, 3, 2)
    # Cycles' bump terminator term: Conty Estevez et al.'s, its smoothing gated per material by
    # the bump map correction, in 4.5.15 and 5.x; Chiang et al.'s in 4.2.13 (both measured
    # against Cycles' bake in tests/blender/test_ray_direct.py; 4.3 and 4.4 not checked)
    corr_of_slot = np.array([bool(getattr(getattr(s.material, "cycles", None),
                                          "use_bump_map_correction", True))
                             for s in obj.material_slots] or [True])
    correction = corr_of_slot[np.clip(mat_index[poly], 0, len(corr_of_slot) - 1)]
    bump = "conty" if bpy.app.version >= BUMP_CONTY_FROM else "chiang"
    samples = texel_samples(uv, resolution)
    if samples.size == 0:
        from .cycles_bake import BakeInputError

        raise BakeInputError(f"{obj.name}: its UV map covers no texel centre at {resolution}^2 "
                             "(UV islands smaller than a texel, or outside 0..1); unwrap it "
                             "(UV > Unwrap) or raise the resolution")
    sampled = getattr(Ns_image, "normal_set", None)   # TexelNormals.normal_set (a method)
    if sampled is not None:
        Ns_image, Ns_offsets = Ns_image.mean, Ns_image.offsets
    Ns = None if Ns_image is None else np.asarray(Ns_image, np.float64).reshape(-1, 3)[samples.texel]
    if Ns is not None:   # texels the normal bake left empty keep the smooth normal
        Ns = np.where(np.linalg.norm(Ns, axis=1, keepdims=True) > 0.5, Ns, np.nan)
    corner_normals, smooth = cn[loops].reshape(-1, 3, 3), m.smooth[poly]
    cutoff = float(getattr(obj, "shadow_terminator_geometry_offset", 0.1))
    points = shading_points(m.co, tri, corner_normals, smooth, samples.triangle, samples.bary,
                            cutoff=cutoff, mirrored=m.mirrored, Ns=None, bump=bump,
                            correction=correction)
    if footprint:
        from ...lt_addon.rays.footprint import Footprint, jitter_box

        # the jitter box of the Blender that bakes: half a texel up to 5.2.0, a whole one from 5.2.1
        points.footprint = Footprint(m.co, tri, corner_normals, smooth, cutoff, m.mirrored, bump,
                                     correction, uv, resolution, samples.texel,
                                     samples.triangle, samples.bary,
                                     box=jitter_box(bpy.app.version))
    if Ns is not None:
        bad = np.isnan(Ns).any(axis=1)
        Ns[bad] = points.N[bad]
        points.Ns = Ns / np.linalg.norm(Ns, axis=1, keepdims=True)
        if sampled is not None:      # (weighed as Cycles' jitter: on the centre's triangle)
            from ...lt_addon.rays.normal_samples import weights

            def weigh(rows):
                t = uv[samples.triangle[rows]]
                centre = np.einsum("mk,mkj->mj", samples.bary[rows], t)
                return weights(t, centre, Ns_offsets, resolution)

            points.normal_set = sampled(samples.texel, points.N, points.correction, bump,
                                        None if Ns_offsets is None else weigh)
            if points.normal_set is not None:   # their mean, of the samples that count
                Ns = points.Ns.copy()           # (a new array: mapped() keys on it)
                Ns[points.normal_set.rows] = points.normal_set.shared.mean
                points.Ns = Ns
    return samples, points
