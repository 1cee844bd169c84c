"""The bounce terms of a material bake gathered by rays through a BVH of the scene (bpy).

:mod:`..lt_addon.transport.gathered_transfer` says what is gathered and why (the rays a
receiver casts do not depend on the light, so one gather serves every light direction). This
module is its Blender side: :class:`GatherScene` reads every rendered mesh of the scene as the
gated Cycles bake sees it -- each face corner with its region (editable material, or the fixed
rest) and the diffuse colour it reflects with (white on editable regions, the material's own
base colour elsewhere, :func:`..base.materials.material_colour`) -- casts the cosine-weighted
rays of a block of origins through the :class:`.direct_rays.ReceiverRays` BVH (the ray
engine, :func:`..base.direct_rays.ray_engine`), and gives the exact direct light at every
corner (a shadow ray per corner origin, the same rays that equal Cycles' bounce-free bake in
the tests).

What it models as Cycles' gated bake does: Diffuse BSDFs of each material's base colour, both
sides of a face lit (a ray meeting a face from behind sees that side's direct light), light
paths of at most two bounces. Not modelled: the back sides' own second bounce, textures (the
viewport colour stands in, as in the Cycles bake), objects whose ray visibility differs
between shadow and diffuse rays (every shadow caster reflects here).
"""

from __future__ import annotations

import bpy
import numpy as np

from ...lt_addon.geometry.barycentric import barycentric
from ...lt_addon.transport import gathered_transfer as gt
from ..base.direct_rays import ReceiverRays, shadow_casters

#: Origins per gather chunk (a cancelled bake resumes from whole chunks; about 1.3 s of rays
#: at 1,024 rays each here).
CHUNK_ORIGINS = 256


def _corner_faces(mesh) -> tuple:
    """(face of each corner (C,), material index of each face (F,)) of an evaluated mesh."""
    F = len(mesh.polygons)
    start, total = np.empty(F, np.int64), np.empty(F, np.int64)
    mesh.polygons.foreach_get("loop_start", start)
    mesh.polygons.foreach_get("loop_total", total)
    face = np.zeros(len(mesh.loops), np.int64)
    for f in np.argsort(start, kind="stable"):   # a face's corners are contiguous
        face[start[f]:start[f] + total[f]] = f
    mi = np.zeros(F, np.int64)
    if F:
        mesh.polygons.foreach_get("material_index", mi)
    return face, mi


class GatherScene:
    """Every rendered mesh of ``scene`` as emitters and ray origins of the gather.

    Parameters
    ----------
    scene : bpy.types.Scene
    regions : list of str
        The editable material names (region ``i + 1``); every other material is region 0.

    Attributes
    ----------
    objects : list of (name, corners)
        The casters in stacking order of the corners.
    front : ReceiverRays
        Per-corner rays of every caster (their origins are the gather's origins).
    tri_corners : (T, 3) int64
        The global corners of each BVH triangle (the BVH's polygon index).
    corner_region : (C,) int16; corner_albedo : (C, 3) float64
    notes : list of str
        Why a material reflects its viewport colour (:func:`..base.materials.material_colour`).
    """

    def __init__(self, scene, regions: list):
        from ..base.materials import material_colour

        self.scene = scene
        self.regions = list(regions)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        casters = shadow_casters(scene)
        self.objects, tris, region, albedo, self.notes, offset = [], [], [], [], [], 0
        for o in casters:
            ev = o.evaluated_get(depsgraph)
            mesh = ev.to_mesh()
            try:
                mesh.calc_loop_triangles()
                tl = np.empty(len(mesh.loop_triangles) * 3, np.int64)
                mesh.loop_triangles.foreach_get("loops", tl)
                if np.linalg.det(np.array(o.matrix_world, np.float64)[:3, :3]) < 0:
                    # mirrored (negative scale): its world winding turns inward; reversed, the
                    # triangles' normals (the front-side test of the gather) face out as
                    # Cycles' flipped geometric normal does
                    tl = tl.reshape(-1, 3)[:, ::-1].ravel()
                face, mi = _corner_faces(mesh)
                n = len(mesh.loops)
            finally:
                ev.to_mesh_clear()
            mats = [s.material for s in o.material_slots] or [None]
            reg, col = [], []
            for m in mats:
                r = self.regions.index(m.name) + 1 if m is not None and m.name in self.regions \
                    else 0
                c, note = (np.ones(3), None) if r else material_colour(m)
                if note and note not in self.notes:
                    self.notes.append(note)
                reg.append(r)
                col.append(c)
            slot = np.clip(mi[face], 0, len(mats) - 1) if n else np.zeros(0, np.int64)
            region.append(np.asarray(reg, np.int16)[slot])
            albedo.append(np.asarray(col, np.float64).reshape(-1, 3)[slot])
            tris.append(tl.reshape(-1, 3) + offset)
            self.objects.append((o.name, n))
            offset += n
        if not offset:
            raise ValueError("the scene has no rendered meshes to gather light from")
        # the gather's bounce rays meet the shadow casters: an object that reflects light but
        # casts no shadow, or casts one but is not seen by bounce rays, is not modelled (said)
        from ..base.direct_rays import CASTER_TYPES
        from ..base.visibility import rendered_names

        rendered = rendered_names()
        for o in scene.objects:
            if o.type not in CASTER_TYPES or o.name not in rendered:
                continue
            shadow = getattr(o, "visible_shadow", True)
            diffuse = getattr(o, "visible_diffuse", True)
            if shadow != diffuse:
                note = (f"{o.name}: {'casts no shadow but reflects light' if diffuse else 'casts a shadow but bounce rays pass through it'} "
                        "(Ray Visibility); the material edits' bounce light treats it as "
                        f"{'absent' if diffuse else 'a reflecting surface'} (not modelled: "
                        "set both Shadow and Diffuse alike for an exact bake)")
                if note not in self.notes:
                    self.notes.append(note)
        self.front = ReceiverRays(scene, self.objects, "CORNER")
        self._back = None
        self.tri_corners = np.concatenate(tris)
        self.corner_region = np.concatenate(region)
        self.corner_albedo = np.concatenate(albedo)
        self.corners = offset
        p = self.front.points
        a, b, c = (p[self.tri_corners[:, k]] for k in range(3))
        self._tri = (a, b, c, np.cross(b - a, c - a))   # corners and (unnormalised) normal
        self._offsets = dict(zip([n for n, _ in self.objects],
                                 np.cumsum([0] + [n for _, n in self.objects])[:-1]))

    @property
    def origins(self) -> int:
        return len(self.front.origins)

    def gather(self, start: int, stop: int, rays: int, seed: int = 0) -> np.ndarray:
        """Transfer entries (:data:`..lt_addon.transport.gathered_transfer.ENTRY`) of origins
        ``start:stop``, ``rays`` cosine-weighted rays each; the same entries for the same
        arguments in any process (the lattice's shifts come from ``(seed, start)``)."""
        ids = np.arange(start, stop)
        rng = np.random.default_rng([int(seed), int(start)])
        d = gt.cosine_directions(self.front.origin_normals[ids], rays,
                                 rng.random((len(ids), 2))).reshape(-1, 3)
        org = np.repeat(self.front.origins[ids], rays, axis=0)
        tri, dist = self.front.engine.nearest(org, d)
        ok = tri >= 0
        ti = tri[ok]
        a, b, c, n = (x[ti] for x in self._tri)
        point = org[ok] + dist[ok, None] * d[ok]
        front = np.einsum("ij,ij->i", d[ok], n) < 0.0
        return gt.hit_entries(np.repeat(ids, rays)[ok], self.tri_corners[ti],
                              barycentric(point, a, b, c), front, self.corners, rays)

    def direct(self, directions, back: np.ndarray | None = None):
        """Exact direct light, visibility x cosine, at every corner for each of ``directions``
        (S, 3): front sides (S, C) float32, and with ``back`` (C,) bool the back sides of
        those corners (S, C) (zero elsewhere; None without)."""
        d = np.asarray(directions, np.float64).reshape(-1, 3)
        front = np.stack([self.front.direct(w) for w in d]) if len(d) else np.zeros(
            (0, self.corners), np.float32)
        if back is None or not np.any(back):
            return front, None
        if self._back is None:
            self._back = ReceiverRays(self.scene, self.objects, "CORNER", side=-1)
        out = np.zeros_like(front)
        for s, w in enumerate(d):
            out[s, back] = self._back.direct(w)[back]
        return front, out

    def receiver_matrix(self, objects, domain: str = "POINT"):
        """Sparse (V, C): each receiver of ``objects`` (stacked as the bake stacks them) as the
        mean of its corners (``POINT``) or its own corner (``CORNER``). ValueError when a
        receiver is not a rendered mesh here or its evaluated mesh is not the one baked."""
        from scipy import sparse

        from ..base.meshes import corner_vertices

        sizes = dict(self.objects)
        rows, cols, vals, V = [], [], [], 0
        for o in objects:
            if o.name not in sizes:
                raise ValueError(f"{o.name!r} casts no shadow in the render, so the rays do "
                                 "not see it: make it visible to shadows or bake its bounces "
                                 "with Cycles (--bounce-bake cycles)")
            n = sizes[o.name]
            if n != len(o.data.loops):
                raise ValueError(f"{o.name!r}'s modifiers change its face corners ({n} "
                                 f"rendered, {len(o.data.loops)} in the mesh): apply them or "
                                 "bake its bounces with Cycles (--bounce-bake cycles)")
            corner = self._offsets[o.name] + np.arange(n)
            if domain == "CORNER":
                rows.append(V + np.arange(n))
                vals.append(np.ones(n))
                V += n
            else:
                v = corner_vertices(o.data)
                count = np.bincount(v, minlength=len(o.data.vertices)).astype(np.float64)
                rows.append(V + v)
                vals.append(1.0 / count[v])
                V += len(o.data.vertices)
            cols.append(corner)
        return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                          np.concatenate(cols))),
                                 shape=(V, self.corners))

    def transfer(self, entries, objects, domain: str = "POINT") -> gt.GatheredTransfer:
        """The :class:`..lt_addon.transport.gathered_transfer.GatheredTransfer` of the gathered
        ``entries`` (all origins) for the receivers ``objects``."""
        return gt.GatheredTransfer(gt.transfer_matrix(entries, self.origins, self.corners),
                                   self.front.origin_of.astype(np.int64), self.corner_region,
                                   self.corner_albedo, self.receiver_matrix(objects, domain),
                                   len(self.regions) + 1)


def gather_chunks(origins: int) -> list:
    """``(start, stop)`` origin ranges of the gather, :data:`CHUNK_ORIGINS` each."""
    return [(a, min(a + CHUNK_ORIGINS, origins)) for a in range(0, origins, CHUNK_ORIGINS)]
