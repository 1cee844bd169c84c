"""The exact direct light of a sun at the receivers of a per-vertex bake, by ray casting (bpy).

A per-vertex bake's direct term ``D`` (S0, V) is exact only at its baked directions: between
them a hard shadow is blended from its neighbours (measured on the demo room, 400 directions:
0.15 of the error of E at suns that are not baked directions, where the two truth seeds differ
by 0.02). Under a sun the direct term is visibility x cosine, which a ray per receiver gives
exactly at any direction: :class:`ReceiverRays` keeps a BVH of the scene's rendered shadow
casters (not instances) and the receivers' points and normals, and casts one ray per lit
receiver towards the sun (``rays`` over the disc of a sun wider than :data:`HARD_SUN_DEG`), or
only where the baked directions around the sun disagree (:meth:`ReceiverRays.known_from`).
The rays go through the texture bake's engine (:class:`...lt_addon.rays.engine.Occluder`,
Embree, batched on every core); where ``embreex`` cannot be imported, through
``mathutils.bvhtree`` one Python call per ray (:class:`MathutilsOccluder`, the same answers).

What Cycles bakes and this reproduces (checked against ``D`` at baked directions in the tests):
a value per face corner at the vertex position with the corner's normal; per vertex
(``POINT``) the mean over the vertex's corners. Shadow rays start a little off the surface
along the normal and see both sides of every face.

A shadow edge that passes exactly through a vertex (a wall's top edge casting along a grid
diagonal: on the demo room at a 45-degree sun, 18 of 4,454 vertices) is a tie: Cycles starts
each corner's ray at the vertex on its own triangle and the float rounding splits them, about
half lit -- the mean of the faces around the vertex. One ray per vertex says all or nothing
(measured: 0.065 of the error of E at that sun, the whole direct error). So under a hard sun,
where a vertex's visibility differs from a neighbour's (a shadow edge is next to it), each of
its corners casts again from a point just inside its own face (:data:`RAY_OFFSET`): away from
a tie this changes nothing, at a tie it splits the corners by the side of the edge their faces
lie on.
"""

from __future__ import annotations

import numpy as np

#: A sun at most this wide (degrees) is treated as a point: one ray per receiver.
HARD_SUN_DEG = 0.6
#: Offset of a ray's origin along the receiver's normal (metres), against self-hits.
RAY_OFFSET = 1e-4
#: ... and as far towards the centre of the receiver's faces: a point on the edge of a face
#: is taken on the face's side of a surface standing there (the floor's edge at the foot of
#: a wall sees through the wall no light from behind it, as in Cycles).


#: Object types whose evaluated geometry casts shadows (those ``to_mesh`` can triangulate).
CASTER_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}


class MathutilsOccluder:
    """:class:`...lt_addon.rays.engine.Occluder`'s two queries through ``mathutils.bvhtree``,
    one Python call per ray: the fallback where ``embreex`` cannot be imported."""

    def __init__(self, vertices, triangles):
        from mathutils.bvhtree import BVHTree

        self.tree = BVHTree.FromPolygons(np.asarray(vertices, np.float64).tolist(),
                                         np.asarray(triangles, np.int64).tolist(),
                                         all_triangles=True)
        self.rays = 0

    def _hits(self, origins, directions) -> list:
        from mathutils import Vector

        o = np.asarray(origins, np.float64).reshape(-1, 3)
        d = np.broadcast_to(np.asarray(directions, np.float64).reshape(-1, 3), o.shape)
        self.rays += len(o)
        return list(map(self.tree.ray_cast, map(Vector, o.tolist()), map(Vector, d.tolist())))

    def occluded(self, origins, directions) -> np.ndarray:
        hits = self._hits(origins, directions)
        return np.fromiter((h[0] is not None for h in hits), bool, len(hits))

    def nearest(self, origins, directions) -> tuple:
        hits = self._hits(origins, directions)
        tri = np.fromiter((-1 if h[2] is None else h[2] for h in hits), np.int64, len(hits))
        dist = np.fromiter((0.0 if h[3] is None else h[3] for h in hits), np.float64, len(hits))
        return tri, dist


def ray_engine(vertices, triangles):
    """(occluder, name): Embree's :class:`...lt_addon.rays.engine.Occluder` over the
    world-space ``triangles`` (T, 3) of ``vertices`` (N, 3), or :class:`MathutilsOccluder`
    where ``embreex`` cannot be imported (name "mathutils")."""
    from ...lt_addon.rays import engine

    ok, why = engine.available()
    if ok:
        return engine.Occluder(vertices, triangles), why
    return MathutilsOccluder(vertices, triangles), "mathutils"


def shadow_casters(scene):
    """The scene's rendered shadow casters (instances and point clouds, volumes not): in the
    render of the context's view layer (:func:`.visibility.rendered_names`: neither their own
    camera icon nor their collections' off, nor excluded) and visible to shadow rays."""
    from .visibility import rendered_names

    rendered = rendered_names()
    return [o for o in scene.objects if o.type in CASTER_TYPES and o.name in rendered
            and getattr(o, "visible_shadow", True)]


def _mesh_arrays(obj, depsgraph, receiver: bool = True):
    """World-space vertices (N, 3), corner vertex indices (C,), corner normals (C, 3), loop
    triangles (T, 3), the centre of each corner's face (C, 3) and the next corner round that
    face (C,) of the evaluated mesh of ``obj``; a caster (``receiver=False``) needs only the
    vertices and triangles (the rest None)."""
    from .ray_scene import mesh_arrays

    m = mesh_arrays(obj, depsgraph)
    if not receiver:
        return m.co, None, None, m.tri, None, None, None
    start, total = m.loop_start, m.loop_total
    F = len(start)
    face_of = np.repeat(np.arange(F), total)[np.argsort(np.repeat(start, total)
                                                         + _ranks(total), kind="stable")]
    # the next corner round each corner's face: the face's edges as corner pairs
    first = start[face_of]
    following = first + (np.arange(len(face_of)) - first + 1) % total[face_of]
    return (m.co, m.corner_vertex, m.corner_normals, m.tri, m.face_centre[face_of], following,
            face_of)


def _vertex_bake_points(obj, depsgraph):
    """Cycles' vertex-bake shading points of ``obj``'s evaluated mesh
    (:func:`...lt_addon.rays.vertex_points.vertex_bake_points`): (ShadingPoints, their corners
    (P,), the vertex of every corner (C,))."""
    from ...lt_addon.rays.vertex_points import vertex_bake_points
    from .ray_scene import mesh_arrays

    m = mesh_arrays(obj, depsgraph)
    points, corner = vertex_bake_points(
        m.co, m.tri, m.loops, m.corner_normals, m.smooth[m.poly],
        cutoff=float(getattr(obj, "shadow_terminator_geometry_offset", 0.1)),
        mirrored=m.mirrored)
    return points, corner, m.corner_vertex


def _ranks(total):
    """0, 1, .., n-1 for each run length n of ``total`` (a face's corner offsets)."""
    ends = np.cumsum(total)
    return np.arange(ends[-1] if len(ends) else 0) - np.repeat(ends - total, total)


class ReceiverRays:
    """Ray-cast direct light for the stacked receivers of a per-vertex bake.

    Parameters
    ----------
    scene : bpy.types.Scene
        Every rendered mesh of it casts shadows (as in the bake).
    objects : list of (name, count)
        The receivers in stacking order, as :attr:`..lt_addon.transport.ptt.TransferTensors.objects`.
    domain : "POINT" or "CORNER"
        A value per vertex (the mean of its corners) or per face corner.
    side : 1 or -1
        The faces' front sides (as Cycles bakes a receiver) or their back sides (what a ray
        meeting a face from behind sees lit: :mod:`.bounce_rays`).
    """

    def __init__(self, scene, objects, domain: str = "POINT", side: int = 1):
        import bpy

        depsgraph = bpy.context.evaluated_depsgraph_get()
        verts, tris, offset = [], [], 0
        for o in shadow_casters(scene):
            co, _, _, tri, _, _, _ = _mesh_arrays(o, depsgraph, receiver=False)
            verts.append(co)
            tris.append(tri + offset)
            offset += len(co)
        if not verts:
            raise ValueError("nothing in the scene casts shadows")
        # the triangles in this order: a hit's triangle is a row of them (bounce_rays)
        self.engine, self.engine_name = ray_engine(np.concatenate(verts), np.concatenate(tris))
        self.domain = domain
        self.objects = [(name, int(count)) for name, count in objects]
        self._bake = None   # Cycles' vertex-bake points (prepare_bake)
        self.bake_engine = None   # what bake_rows casts against (None: self.engine)
        self.cast = 0   # origins the last direct() cast rays from
        points, normals, inward, groups, nexts, faces, starts, corners = [], [], [], [], [], [], 0, 0
        n_faces = 0
        for name, count in objects:
            co, corner_v, cn, _, fc, following, face_of = _mesh_arrays(bpy.data.objects[name],
                                                                       depsgraph)
            n_el = len(corner_v) if domain == "CORNER" else len(co)
            if n_el != count:
                raise ValueError(f"{name!r} has {n_el} {'corners' if domain == 'CORNER' else 'vertices'} "
                                 f"now, the bake {count}: bake the materials again")
            points.append(co[corner_v])                 # every corner, at its vertex
            normals.append(cn if side > 0 else -cn)
            inward.append(fc - co[corner_v])
            groups.append((corner_v if domain == "POINT" else np.arange(len(corner_v))) + starts)
            nexts.append(following + corners)
            faces.append(face_of + n_faces)
            n_faces += int(face_of.max()) + 1 if len(face_of) else 0
            starts += count
            corners += len(corner_v)
        self.points = np.concatenate(points)            # (C, 3) world
        self.normals = np.concatenate(normals)          # (C, 3) unit
        self.group = np.concatenate(groups)             # (C,) receiver of each corner
        self.count = starts
        self.per_receiver = np.bincount(self.group, minlength=starts).astype(np.float64)
        # one ray origin per point and normal: the corners of a smooth or flat vertex share
        # one, a hard edge's faces get one each (their visibility differs near the edge);
        # off the surface along the normal, and towards the centre of the corners' faces
        key = np.concatenate([np.round(self.points, 6), np.round(self.normals, 3)], axis=1)
        _, origin_of = np.unique(key, axis=0, return_inverse=True)
        self._origin_of = origin_of.reshape(-1)
        n_orig = int(self._origin_of.max()) + 1 if len(self._origin_of) else 0
        # towards the faces' centres along the surface: in the tangent plane of the corner's
        # normal (a curved mesh's face centres lie below its vertices; that part pointed the
        # origin back into the surface: a 12 x 8 smooth ball's pole and equator shadowed
        # themselves at 33 of 1,290 values, where Cycles lights them)
        towards = np.concatenate(inward)
        towards -= np.sum(towards * self.normals, axis=1, keepdims=True) * self.normals
        towards /= np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), 1e-30)
        base, normal = np.zeros((n_orig, 3)), np.zeros((n_orig, 3))
        base[self._origin_of] = self.points
        normal[self._origin_of] = self.normals
        mean_t = np.zeros((n_orig, 3))
        np.add.at(mean_t, self._origin_of, towards)
        mean_t -= np.sum(mean_t * normal, axis=1, keepdims=True) * normal
        norm_t = np.linalg.norm(mean_t, axis=1, keepdims=True)
        mean_t = np.where(norm_t > 1e-6, mean_t / np.maximum(norm_t, 1e-30), 0.0)
        self._origins = base + RAY_OFFSET * (normal + mean_t)
        self.origin_normals = normal   # (origins, 3) unit: the normal each origin stands on
        # each corner's own origin, inside its face (for ties, see the module docstring), and
        # the faces' edges as pairs of corners
        self._corner_origins = self.points + RAY_OFFSET * (self.normals + towards)
        self._edge_from = np.arange(corners)
        self._edge_to = np.concatenate(nexts) if nexts else np.zeros(0, np.int64)
        self._face = np.concatenate(faces) if faces else np.zeros(0, np.int64)
        self._faces = n_faces
        self.ties = 0   # corners the last direct() cast again at a shadow edge

    def prepare_bake(self) -> None:
        """Read Cycles' vertex-bake shading points of the receivers (each face corner inside
        its first triangle, :mod:`...lt_addon.rays.vertex_points`) for :meth:`bake_rows`: call
        it with the depsgraph evaluated as the bake evaluates it (the render's geometry)."""
        import bpy

        from ...lt_addon.rays.contact import Contact
        from ...lt_addon.rays.shading import ShadingPoints
        from . import ray_scene

        depsgraph = bpy.context.evaluated_depsgraph_get()
        parts, groups, start = [], [], 0
        for name, count in self.objects:
            points, corner, corner_v = _vertex_bake_points(bpy.data.objects[name], depsgraph)
            parts.append(points)
            groups.append((corner_v[corner] if self.domain == "POINT" else corner) + start)
            start += count
        # corners touching another object's surface (a box's bottom on its floor): Cycles'
        # rays meet it at once (lt_addon/rays/contact.py)
        self.touching = ray_scene.with_contacts(
            depsgraph, [(name, p) for (name, _), p in zip(self.objects, parts)])
        fields = ("P", "Ng", "N", "Ns", "lift", "cutoff", "correction")
        points = ShadingPoints(*(np.concatenate([getattr(p, f) for p in parts])
                                 for f in fields[:6]), parts[0].bump,
                               np.concatenate([p.correction for p in parts]), parts[0].epsilon,
                               Contact.join([p.contact for p in parts],
                                            [p.size for p in parts]))
        self._bake = (points, np.concatenate(groups))

    def bake_rows(self, directions) -> np.ndarray:
        """What Cycles' 1-spp vertex bake of a hard sun gives per receiver (S, count) float32,
        visibility x cosine per unit normal irradiance, for unit ``directions`` (S, 3): from
        the points :meth:`prepare_bake` read, all directions in batched engine calls."""
        from ...lt_addon.rays.vertex_points import vertex_rows

        if self._bake is None:
            self.prepare_bake()
        points, group = self._bake
        return vertex_rows(self.bake_engine or self.engine, points, group, self.count,
                           directions)

    @property
    def origin_of(self) -> np.ndarray:
        """(C,) the ray origin of each corner (corners of one point and normal share one)."""
        return self._origin_of

    @property
    def origins(self) -> np.ndarray:
        """(origins, 3) world: the ray origins, just off the surface."""
        return self._origins

    def receiver_frames(self):
        """Each receiver's position (V, 3) and unit normal (V, 3): the mean over its corners."""
        pos = np.zeros((self.count, 3))
        nrm = np.zeros((self.count, 3))
        np.add.at(pos, self.group, self.points)
        np.add.at(nrm, self.group, self.normals)
        pos /= np.maximum(self.per_receiver, 1)[:, None]
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
        return pos, nrm

    def direct(self, direction, angle_deg: float = 0.0, rays: int = 16,
               known=None) -> np.ndarray:
        """Visibility x cosine (V,) float32 per unit normal irradiance from a sun towards
        ``direction`` (3,) of angular diameter ``angle_deg``: one ray per receiver for a hard
        sun, ``rays`` stratified over the disc otherwise. ``known`` (V,): a visibility the
        caller already knows per receiver (1 lit, 0 dark, NaN: cast), see :meth:`known_from`;
        only the other receivers are cast. ``self.cast`` is how many origins were."""
        w = np.asarray(direction, dtype=np.float64)
        w = w / np.linalg.norm(w)
        cos = np.maximum(self.normals @ w, 0.0)                 # (C,)
        cast = cos > 0
        if known is not None:
            k = np.asarray(known, dtype=np.float64)[self.group]   # (C,)
            cast &= np.isnan(k)
        dirs = [w] if angle_deg <= HARD_SUN_DEG else disc_directions(w, angle_deg, rays)
        vis = self._visible_where(cast, dirs)[self._origin_of]
        if known is not None:
            vis = np.where(np.isnan(k), vis, k)
        self.ties = 0
        if len(dirs) == 1:   # a soft sun's disc already splits an edge's vertices
            vis = self._split_ties(vis, cos > 0, cast, w)
        per_corner = cos * vis
        out = np.bincount(self.group, weights=per_corner, minlength=self.count)
        return (out / np.maximum(self.per_receiver, 1)).astype(np.float32)

    def _split_ties(self, vis, facing, cast, w) -> np.ndarray:
        """``vis`` (C,) with the corners of every cast vertex next to a shadow edge (a
        facing neighbour round a face sees the sun differently) cast again from inside their
        own faces towards ``w``: a shadow edge through the vertex itself splits them as Cycles
        does (see the module docstring)."""
        a, b = self._edge_from, self._edge_to
        edge = facing[a] & facing[b] & (vis[a] != vis[b])
        near = np.zeros(len(self._origins), bool)
        near[self._origin_of[a[edge]]] = True
        near[self._origin_of[b[edge]]] = True
        # only the corners on a face the edge crosses: a corner whose face lies on one side
        # of it is on that side whether or not the edge passes through its vertex (half the
        # rays at 13K vertices, the same values)
        crossed = np.zeros(self._faces, bool)
        crossed[self._face[a[edge]]] = True
        idx = np.nonzero(near[self._origin_of] & cast & crossed[self._face])[0]
        self.ties = len(idx)
        if not len(idx):
            return vis
        out = vis.copy()
        out[idx] = ~self.engine.occluded(self._corner_origins[idx], w)
        return out

    def mean_cos(self, directions) -> np.ndarray:
        """(K, V) mean over each receiver's corners of ``max(0, n . w)`` for K directions."""
        w = np.asarray(directions, np.float64).reshape(-1, 3)
        if not hasattr(self, "_flat"):
            # receivers whose corners share one normal (a flat or smooth vertex; not a hard
            # edge's): their mean is the cosine of that normal, no per-corner sum (at 13K
            # vertices 0.3 ms instead of 1.5)
            first = np.zeros((self.count, 3))
            first[self.group] = self.normals
            self._flat = np.bincount(self.group, weights=np.any(
                np.abs(self.normals - first[self.group]) > 1e-6, axis=1),
                minlength=self.count) == 0
            self._flat_normal = first
            self._edge_corners = np.nonzero(~self._flat[self.group])[0]
        out = np.maximum(w @ self._flat_normal.T, 0.0)                           # (K, V)
        e = self._edge_corners
        if len(e):
            cos = np.maximum(w @ self.normals[e].T, 0.0)
            sums = np.stack([np.bincount(self.group[e], weights=c, minlength=self.count)
                             for c in cos])
            out = np.where(self._flat[None], out, sums / np.maximum(self.per_receiver, 1))
        return out

    def known_from(self, D_rows, directions) -> np.ndarray:
        """Visibility (V,) the baked direct term already tells at a sun between ``directions``
        (K, 3), the baked directions its weights touch, with ``D_rows`` (K, V) their values of
        ``D`` (visibility x cosine): 1 where the receiver is fully lit at all of them, 0 where
        it is dark (and faces them) at all, NaN where they disagree -- a shadow edge passes
        between them -- or say nothing (facing away); only those need a ray. A shadow that
        falls between the baked directions and on none of them is missed (an occluder
        thinner than their spacing)."""
        D = np.asarray(D_rows, np.float64)
        c = self.mean_cos(directions)
        facing = c > 1e-4
        lit = facing & (D >= 0.999 * c - 1e-6)
        dark = facing & (D <= 1e-3 * c)
        out = np.full(self.count, np.nan)
        out[np.all(lit, axis=0)] = 1.0
        out[np.all(dark, axis=0)] = 0.0
        return out

    def _visible_where(self, lit, directions) -> np.ndarray:
        """Mean visibility (origins,) over ``directions`` of the origins with a lit corner."""
        need = np.zeros(len(self._origins), bool)
        need[self._origin_of[lit]] = True
        idx = np.nonzero(need)[0]
        vis = np.zeros(len(self._origins))
        self.cast = len(idx)
        if not len(idx):
            return vis
        d = np.asarray(directions, np.float64).reshape(-1, 3)
        o = self._origins[idx]
        blocked = self.engine.occluded(np.tile(o, (len(d), 1)), np.repeat(d, len(o), axis=0))
        vis[idx] = len(d) - blocked.reshape(len(d), len(o)).sum(axis=0)
        return vis / len(d)


#: How a bake's direct term is made: "auto" (rays where they reproduce the scene, else
#: Cycles), "rays" (refuse a scene they cannot), "cycles" (a 1-spp Cycles bake per direction).
DIRECT_BAKES = ("auto", "rays", "cycles")
#: Directions of a direct set that Cycles also bakes when rays make it: the report's check of
#: the rays against Cycles (``direct.vs_cycles``), spread evenly over the set.
DIRECT_CHECKS = 8


def check_indices(S: int) -> np.ndarray:
    """The directions of a direct set of ``S`` that Cycles checks when rays bake the direct
    term: :data:`DIRECT_CHECKS` of them, spread evenly over the set (all of a smaller one)."""
    return np.unique(np.linspace(0, S - 1, min(DIRECT_CHECKS, S)).round().astype(np.int64))


def direct_agreement(cycles: np.ndarray, rays: np.ndarray) -> dict:
    """How far the rays' direct light ``rays`` (S, V) is from Cycles' bake of it ``cycles``
    (S, V) at the same directions: the relative difference over all values and the share of
    values more than 1e-4 apart (a vertex where two edges meet exactly may differ: Cycles'
    intersection tie-break)."""
    a, b = np.asarray(cycles, np.float64), np.asarray(rays, np.float64)
    off = np.abs(a - b) > 1e-4
    return {"rel_difference": round(float(np.linalg.norm(a - b)
                                          / max(np.linalg.norm(a), 1e-30)), 6),
            "values_apart": round(float(off.mean()) if off.size else 0.0, 6)}


def bake_rays(scene, receivers, domain: str, mode: str, instances: bool = False):
    """``(choice, rays)`` for a per-vertex bake's direct term: how it is made, ``{"engine":
    "rays" | "cycles", "why": ...}`` (with "library" for rays), and the :class:`ReceiverRays`
    of ``receivers`` ((name, count) in stacking order) read with the render's geometry (None
    with Cycles). With ``instances`` its :meth:`ReceiverRays.bake_rows` cast against every
    shadow caster of the render, instances included (the texture bake's
    :func:`.ray_scene.casters`); without, an instanced caster is left to Cycles (the material
    bake: its gathered bounces read each object once). ``mode`` (:data:`DIRECT_BAKES`) "rays"
    on a scene rays cannot reproduce -- see-through or displaced shadow casters, hair,
    volumes, modifiers that change a receiver's vertices in the render -- raises
    BakeInputError with the reasons."""
    from ...lt_addon.rays import engine
    from . import ray_scene
    from .cycles_bake import BakeInputError

    if mode == "cycles":
        return {"engine": "cycles", "why": "asked for (--direct cycles)"}, None
    ok, lib = engine.available()
    why, rays = ([] if ok else [f"no ray engine: {lib}"]), None
    if ok:
        import bpy

        with ray_scene.RenderGeometry(scene) as depsgraph:
            why = ray_scene.unsupported(scene, depsgraph, [bpy.data.objects[n]
                                                           for n, _ in receivers])
            inst = sorted({i.object.original.name for i in depsgraph.object_instances
                           if i.is_instance and i.object.type in ray_scene.CASTER_TYPES
                           and getattr(i.object.original, "visible_shadow", True)})
            if inst and not instances:   # ReceiverRays reads each caster object once
                why.append(f"instanced shadow casters ({', '.join(inst[:3])}"
                           f"{', ...' if len(inst) > 3 else ''})")
            if not why:
                try:
                    rays = ReceiverRays(scene, receivers, domain)
                    rays.prepare_bake()      # the render's geometry, as the bake reads it
                    if instances:
                        V, T, _ = ray_scene.casters(depsgraph)
                        rays.bake_engine = engine.Occluder(V, T)
                except ValueError as exc:   # a modifier changes the receivers' vertices
                    why.append(str(exc))
    if why:
        if mode == "rays":
            raise BakeInputError("--direct rays cannot reproduce this scene's direct light: "
                                 + "; ".join(why) + " (use --direct cycles or auto)")
        return {"engine": "cycles", "why": "rays cannot reproduce: " + "; ".join(why)}, None
    return {"engine": "rays", "why": "the scene is supported", "library": lib}, rays


def disc_directions(w, angle_deg: float, n: int) -> np.ndarray:
    """``n`` unit directions stratified over the sun disc of angular diameter ``angle_deg``
    around ``w`` (a Fibonacci spiral: fixed, so the same light gives the same value)."""
    w = np.asarray(w, dtype=np.float64)
    a = np.cross(w, [0.0, 0.0, 1.0] if abs(w[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(w, a)
    half = np.radians(angle_deg) / 2.0
    k = np.arange(n) + 0.5
    r = np.tan(half) * np.sqrt(k / n)
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    d = w[None] + r[:, None] * (np.cos(phi)[:, None] * a + np.sin(phi)[:, None] * b)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


_RAYS: dict = {}


def _scene_stamp(scene) -> str:
    """A cheap fingerprint of the shadow casters: every rendered mesh's name, transform and
    vertex positions (0.2 ms at 13K vertices), so a moved or edited mesh rebuilds the BVH."""
    import hashlib

    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    h = hashlib.sha1()
    for o in sorted(shadow_casters(scene), key=lambda o: o.name):
        h.update(o.name.encode())
        h.update(np.asarray(o.matrix_world, np.float32).tobytes())
        data = o.evaluated_get(depsgraph).data   # a mesh's: after modifiers and poses
        if o.type == "MESH" and data is not None:
            co = np.empty(len(data.vertices) * 3, np.float32)
            position = data.attributes.get("position")
            if position is not None:   # 12x faster than vertices' "co" (1.0 -> 0.08 ms)
                position.data.foreach_get("vector", co)
            else:
                data.vertices.foreach_get("co", co)
            h.update(co.tobytes())
    return h.hexdigest()


def exact_direct(scene, tensors, light, everywhere: bool = True) -> np.ndarray | None:
    """The exact direct term (V,) of ``light`` (a ``ptt.Sun``) for the receivers of
    ``tensors`` in ``scene`` -- pass it as ``direct=`` to the tensors' relight. A ray per lit
    receiver; with ``everywhere=False`` only where the baked directions around the sun
    disagree (:meth:`ReceiverRays.known_from`: measured 4x faster at 13K vertices, but on the
    demo room it missed shadow corners falling between baked directions: the direct part's
    error 0.024 instead of 0.016). The :class:`ReceiverRays` is cached per scene,
    receivers and shadow casters, and the last light's result too (a colour edit casts
    nothing). None when a receiver's mesh no longer has the bake's vertex count (the caller
    keeps ``D``)."""
    from ...lt_addon.transport.texture import sun_weights

    domain = tensors.metadata.get("domain", "POINT")
    key = (scene.name, tuple(tuple(o) for o in tensors.objects), domain)
    stamp = _scene_stamp(scene)
    hit = _RAYS.get(key)
    if hit is None or hit["stamp"] != stamp:
        try:
            hit = {"stamp": stamp, "rays": ReceiverRays(scene, tensors.objects, domain)}
        except (ValueError, KeyError):   # remembered: the next update does not try again
            hit = {"stamp": stamp, "rays": None}
        _RAYS[key] = hit
    if hit["rays"] is None:
        return None
    light_key = (tuple(np.round(light.direction, 9)), float(light.angle_deg), everywhere,
                 id(tensors))
    if hit.get("light") != light_key:
        rays, known = hit["rays"], None
        if not everywhere and tensors.direct.size:
            d0 = tensors.direction_sets()[0]
            idx, _ = sun_weights(d0, light.direction, light.angle_deg)
            if len(idx):
                known = rays.known_from(tensors.direct[idx], d0.directions[idx])
        hit["value"] = rays.direct(light.direction, light.angle_deg, known=known)
        hit["light"], hit["cast"] = light_key, rays.cast
    return hit["value"]
