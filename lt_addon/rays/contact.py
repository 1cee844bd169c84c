"""Shading points that touch another object's surface: what Cycles' shadow ray meets at t ~ 0.

Cycles starts a flat face's shadow ray at the shading point itself and skips only the point's own
triangle (``kernel/integrator/intersect_shadow.h``, ``ray.self``). A surface of *another* object
through the point -- a box standing on a floor, a wall sitting on a slab: the box's bottom face
is coplanar with the floor -- is met at once, so every direction leaving through it is dark.
The ray bake cannot skip one primitive (Embree has no such filter here) and pushes its origin
off the plane instead (:data:`.shading.EPSILON`), which moves the origin *through* that coplanar
surface: the floor is missed and the box's bottom is lit.

Measured on a flat-shaded unit box standing on a 4 m floor (per-vertex bake, ``cube:4``, 96
directions, against Cycles' 1-spp vertex bake of 8 of them): relative difference 0.35, 19 % of
values more than 1e-4 apart, all at the bottom vertices under directions below the horizon
(Cycles 0, rays 0.12).

The rule here: a point is *touching* when a surface of another object crosses the segment
``P +/- 2 eps Ng`` (eps: the origin push). For those points only, a short *contact ray* from just
behind the point's plane (``P - eps/10 n``, ``n`` the normal on ``L``'s side) along ``L`` to the
pushed origin's plane is cast against the other objects alone (the receiver left out, so its own
triangle is not met); a hit means Cycles' ray meets that surface at t ~ 0: dark. A surface
*behind* the point by more than ``eps/10`` is not met (Cycles' ray, starting at P, does not see it
either). Where Cycles lifts the origin (smooth faces near the terminator:
:func:`.shading.shadow_origins`) the ray starts above any such surface and is left as it is.

All positions are world space (metres); the rays are float32 as every other ray of the bake.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The probe's reach off the plane, in units of the origin push: a surface nearer than this to
#: the point (along its normal) is checked per direction.
PROBE = 2.0
#: Where the contact ray starts behind the plane, in units of the push (see the module
#: docstring): exactly coplanar surfaces are crossed well inside the ray, not at its start.
BEHIND = 0.1


@dataclass
class Contact:
    """The points of a :class:`.shading.ShadingPoints` set that touch another object's surface.

    Attributes
    ----------
    others : list of occluders, each of the shadow casters but one receiver (``occluded`` with
        ``tfar``: :class:`.engine.Occluder`);  owner : (P,) int32, the occluder of each point's
        receiver among ``others``, -1 where the point touches nothing.
    """

    others: list
    owner: np.ndarray

    @property
    def touching(self) -> np.ndarray:
        return self.owner >= 0

    @property
    def count(self) -> int:
        return int(np.count_nonzero(self.owner >= 0))

    def subset(self, rows) -> "Contact":
        return Contact(self.others, self.owner[np.asarray(rows, np.int64)])

    @staticmethod
    def join(parts, sizes) -> "Contact | None":
        """One Contact for point sets stacked in order (``parts``: a Contact or None each;
        ``sizes``: their point counts), or None if none touches."""
        if all(p is None for p in parts):
            return None
        others, owners = [], []
        for p, n in zip(parts, sizes):
            if p is None:
                owners.append(np.full(n, -1, np.int32))
                continue
            owners.append(np.where(p.owner >= 0, p.owner + len(others), -1).astype(np.int32))
            others.extend(p.others)
        return Contact(others, np.concatenate(owners))


def near_triangles(vertices, triangles, lo, hi, margin: float) -> np.ndarray:
    """Rows of ``triangles`` (T, 3) whose bounding box meets the box ``[lo, hi]`` (3,) grown by
    ``margin`` metres: the only ones a receiver inside it can touch."""
    V = np.asarray(vertices, np.float64)
    T = np.asarray(triangles, np.int64).reshape(-1, 3)
    if not len(T):
        return np.zeros(0, np.int64)
    corners = V[T]                                     # (T, 3, 3)
    tlo, thi = corners.min(axis=1), corners.max(axis=1)
    lo = np.asarray(lo, np.float64) - margin
    hi = np.asarray(hi, np.float64) + margin
    return np.nonzero(np.all((thi >= lo) & (tlo <= hi), axis=1))[0]


def _push(points) -> np.ndarray:
    """Each point's origin push (P,) in metres, as :meth:`.shading.ShadingPoints.compact`."""
    return points.epsilon * np.maximum(1.0, np.abs(points.P).max(axis=1))


def reach(points) -> float:
    """How far (metres) from its receiver's points another surface can touch one."""
    return float(PROBE * _push(points).max()) * 1.01 if points.size else 0.0


def find(points, others) -> Contact | None:
    """The :class:`Contact` of ``points`` with the surfaces of ``others`` (an occluder without
    the receiver), or None where no point touches one. Two probe rays a point, along both
    sides of its geometric normal across ``+/- PROBE`` pushes."""
    if others is None or not getattr(others, "n_triangles", 0) or not points.size:
        return None
    eps = _push(points)
    P, Ng = points.P, points.Ng
    length = (2 * PROBE * eps).astype(np.float32)
    up = others.occluded(P - PROBE * eps[:, None] * Ng, Ng, tfar=length)
    down = others.occluded(P + PROBE * eps[:, None] * Ng, -Ng, tfar=length)
    hit = up | down
    if not hit.any():
        return None
    owner = np.full(points.size, -1, np.int32)
    owner[hit] = 0
    return Contact([others], owner)


def blocked(points, idx, L, origins) -> np.ndarray:
    """Whether each point ``idx`` (M,) of ``points`` (with a :class:`Contact` in
    ``points.contact``) meets another object's surface at t ~ 0 towards unit ``L`` (3,):
    (M,) bool. ``origins`` (M, 3): the points' shadow-ray origins towards ``L``
    (:func:`.shading.shadow_origins`); where Cycles lifts one off the surface (farther than
    the push) its ray starts above any touching surface and is not checked."""
    idx = np.asarray(idx, np.int64)
    out = np.zeros(len(idx), bool)
    contact = points.contact
    if contact is None or not len(idx):
        return out
    owner = contact.owner[idx]
    L = np.asarray(L, np.float64)
    for k in np.unique(owner[owner >= 0]):
        sel = np.nonzero(owner == k)[0]
        i = idx[sel]
        Ng = points.Ng[i]
        NgL = Ng @ L
        n = Ng * np.where(NgL < 0, -1.0, 1.0)[:, None]
        eps = _push(points)[i]
        height = np.einsum("pj,pj->p", np.asarray(origins, np.float64)[sel] - points.P[i], n)
        flat = height <= 1.5 * eps       # the pushed point (a lifted one starts above it all)
        if not flat.any():
            continue
        sel, i, n, eps, NgL = sel[flat], i[flat], n[flat], eps[flat], NgL[flat]
        origin = points.P[i] - BEHIND * eps[:, None] * n
        length = ((1.0 + BEHIND) * eps / np.maximum(np.abs(NgL), 1e-3)).astype(np.float32)
        out[sel] = contact.others[int(k)].occluded(origin, L, tfar=length)
    return out
