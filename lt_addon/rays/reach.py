"""Where shadow casters can be seen from a shading point: conservative bounds that let the
horizon scan (:mod:`.horizon`) skip rays that cannot meet anything.

The casters' triangles are grouped into boxes (:func:`clusters`, a surface-area-heuristic split,
which isolates large flat triangles such as a ground plane from the small ones of an object on
it). Seen from a point, a box covers an arc of azimuths and a range of elevations
(:func:`reach`); a ray outside every box's reach meets nothing, so the scan does not cast it and
the map is the same bit for bit. A box lying wholly below a point's tangent plane cannot be met
by a ray that leaves the point upwards of that plane (the push of :mod:`.shading` lifts its
origin strictly above it and the ray rises): that is what rules out the ground's own boxes for
the ground's own points, where most of the horizon scan's rays went.

Shapes and units: boxes (C, 2, 3) world metres (``[:, 0]`` minimum corner, ``[:, 1]``
maximum); azimuths ``2 pi a / A`` from +x toward +y; elevations in radians.
"""

from __future__ import annotations

import heapq

import numpy as np

#: Boxes made of the casters' triangles: more fit tighter and cost more per point (the bound
#: is C x P work; 64 on the statue demo's 10.8k triangles: 0.5 s for 110k points).
LEAVES = 64
#: Angular safety margin (radians) around every bound: the rays' directions are float32.
MARGIN = 1e-4


def _area(lo, hi):
    d = np.maximum(hi - lo, 0.0)
    return d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 0] * d[..., 2]


def _split(lo, hi, idx):
    """The surface-area-heuristic split of triangles ``idx``: (left, right) index arrays, or
    None when no split lowers the cost."""
    n = len(idx)
    cen = 0.5 * (lo[idx] + hi[idx])
    best = (_area(lo[idx].min(0), hi[idx].max(0)) * n, None)
    for ax in range(3):
        order = idx[np.argsort(cen[:, ax], kind="stable")]
        l_lo = np.minimum.accumulate(lo[order], axis=0)
        l_hi = np.maximum.accumulate(hi[order], axis=0)
        r_lo = np.minimum.accumulate(lo[order][::-1], axis=0)[::-1]
        r_hi = np.maximum.accumulate(hi[order][::-1], axis=0)[::-1]
        k = np.arange(1, n)                      # left holds the first k
        cost = _area(l_lo[k - 1], l_hi[k - 1]) * k + _area(r_lo[k], r_hi[k]) * (n - k)
        i = int(np.argmin(cost))
        if cost[i] < best[0]:
            best = (cost[i], (order[:k[i]], order[k[i]:]))
    return best[1]


def clusters(vertices, triangles, leaves: int = LEAVES) -> np.ndarray:
    """Boxes (C, 2, 3) float64 around groups of triangles, C <= ``leaves``: the box with the
    largest area x triangles is split first, by the surface-area heuristic. The vertices are
    taken in float32, as the ray engine holds them."""
    V = np.asarray(vertices, np.float32).astype(np.float64)
    T = np.asarray(triangles, np.int64)
    if not len(T):
        return np.zeros((0, 2, 3))
    tri = V[T]
    lo, hi = tri.min(1), tri.max(1)

    def entry(idx):
        return (-float(_area(lo[idx].min(0), hi[idx].max(0)) * len(idx)), int(idx[0]), idx)
    heap, done = [entry(np.arange(len(T)))], []
    while heap and len(heap) + len(done) < leaves:
        _, _, idx = heapq.heappop(heap)
        parts = _split(lo, hi, idx) if len(idx) > 1 else None
        if parts is None:
            done.append(idx)
            continue
        for p in parts:
            heapq.heappush(heap, entry(p))
    groups = done + [e[2] for e in heap]
    return np.stack([np.stack([lo[g].min(0), hi[g].max(0)]) for g in groups])


def reach(boxes, apex, spread, Ng, P, above, azimuths: int):
    """Per point, where a ray that leaves it upwards of its tangent plane can meet a box.

    Parameters
    ----------
    boxes : (C, 2, 3);  apex : (n, 3) the centre of the region the point's ray origins lie in;
    spread : (n, 3) that region's half extents (the boxes are grown by it);  Ng : (n, 3) unit
    geometric normals;  P : (n, 3) the points;  above : (n,) how far above the tangent plane
    every such origin is at least (metres; <= 0: no box is ruled out by the plane);
    azimuths : A.

    Returns
    -------
    covered : (A, n) bool, some box spans the azimuth;  e_lo, e_hi : (n,) radians, the lowest
    and the highest elevation a ray can meet a box at (over all boxes not ruled out; empty,
    ``e_lo > e_hi``, when none is left).
    """
    n = len(apex)
    A = int(azimuths)
    step = 2 * np.pi / A
    flats, signs = [], []
    e_lo = np.full(n, np.inf)
    e_hi = np.full(n, -np.inf)
    for lo, hi in boxes:
        # a box wholly below the tangent plane by more than the origin's height above it
        top = Ng @ (0.5 * (lo + hi)) - np.einsum("pj,pj->p", Ng, P) \
            + np.abs(Ng) @ (0.5 * (hi - lo))
        keep = ~((above > 0) & (top < above))
        if not keep.any():
            continue
        k = np.nonzero(keep)[0]
        c, u = apex[k], spread[k]
        blo, bhi = lo - u, hi + u                               # (m, 3) grown boxes
        # horizontal distances from the apex to the footprint: nearest and farthest
        dx = np.maximum(np.maximum(blo[:, 0] - c[:, 0], c[:, 0] - bhi[:, 0]), 0.0)
        dy = np.maximum(np.maximum(blo[:, 1] - c[:, 1], c[:, 1] - bhi[:, 1]), 0.0)
        smin = np.hypot(dx, dy)
        fx = np.maximum(np.abs(blo[:, 0] - c[:, 0]), np.abs(bhi[:, 0] - c[:, 0]))
        fy = np.maximum(np.abs(blo[:, 1] - c[:, 1]), np.abs(bhi[:, 1] - c[:, 1]))
        smax = np.hypot(fx, fy)
        dz_hi, dz_lo = bhi[:, 2] - c[:, 2], blo[:, 2] - c[:, 2]
        hi_e = np.where(dz_hi >= 0, np.arctan2(dz_hi, smin), np.arctan2(dz_hi, smax))
        lo_e = np.where(dz_lo <= 0, np.arctan2(dz_lo, smin), np.arctan2(dz_lo, smax))
        e_hi[k] = np.maximum(e_hi[k], hi_e + MARGIN)
        e_lo[k] = np.minimum(e_lo[k], lo_e - MARGIN)
        # the arc of azimuths: all of them when the apex is over the footprint, else the
        # corners' angles about the centre's (the footprint subtends less than pi)
        inside = smin <= 0
        mid = np.arctan2(0.5 * (blo[:, 1] + bhi[:, 1]) - c[:, 1],
                         0.5 * (blo[:, 0] + bhi[:, 0]) - c[:, 0])
        rel = []
        for x in (blo[:, 0], bhi[:, 0]):
            for y in (blo[:, 1], bhi[:, 1]):
                t = np.arctan2(y - c[:, 1], x - c[:, 0]) - mid
                rel.append((t + np.pi) % (2 * np.pi) - np.pi)
        rel = np.stack(rel)
        a0 = np.ceil((mid + rel.min(0) - MARGIN) / step).astype(np.int64)
        a1 = np.floor((mid + rel.max(0) + MARGIN) / step).astype(np.int64)
        a0 = np.where(inside, 0, a0)
        a1 = np.where(inside, A - 1, a1)
        width = np.minimum(a1 - a0 + 1, A)                      # azimuths covered, >= 0
        ok = width > 0
        start = np.mod(a0, A)
        end = start + width                                     # exclusive, may pass A
        kk, s, e = k[ok], start[ok], end[ok]
        wrap = e > A
        # +1 where an arc starts, -1 after it ends (a wrapping arc restarts at 0)
        flat = np.concatenate([s * n + kk, np.minimum(e, A) * n + kk, kk[wrap],
                               (e[wrap] - A) * n + kk[wrap]])
        sign = np.concatenate([np.ones(len(kk)), -np.ones(len(kk)), np.ones(int(wrap.sum())),
                               -np.ones(int(wrap.sum()))])
        flats.append(flat)
        signs.append(sign)
    if flats:
        diff = np.bincount(np.concatenate(flats), np.concatenate(signs), (A + 1) * n)
        covered = np.cumsum(diff.reshape(A + 1, n)[:A], axis=0) > 0.5
    else:
        covered = np.zeros((A, n), bool)
    return covered, e_lo, e_hi
