"""One- and two-bounce light gathered by rays once, for every light direction (bpy-free).

The bounce terms of the material tensors (:mod:`.ptt`) were Cycles bakes, one per light
direction, region and gate: each direction's value at a receiver came from that bake's own
16 hemisphere samples. But what a receiver sees of the scene does not depend on the light:
only the light *on* the surfaces it sees does. So here every receiver casts ``N`` cosine-
weighted rays once (the bpy layer, :mod:`..operators.bakes.bounce_rays`), each ray's hit is written
as barycentric weights on the three face corners of the triangle it hits, and the sparse
transfer ``K`` (origins x corners) so gathered turns the direct light at the corners -- exact,
a shadow ray per corner -- into the one-bounce irradiance at the receivers for *any* light
direction, and the one-bounce light at the corners into the two-bounce irradiance (Hasan et al.
2006's direct-to-indirect transfer at vertex resolution). The rays are shared by all directions,
regions and both bounce orders, so 512 rays per receiver cost less than the 16 samples per
direction, region and gate of the Cycles bakes did.

Measured on the demo room (4,454 vertices, 7 held-out suns, 256-spp Cycles truths with 2
bounces; ``benchmarks/bench_materials.py``): evaluated exactly at each sun (no blend between
directions), the relative error of E was 0.0158 / 0.0148 (file colours; 0.88x / 0.82x the
noise floor of two truth seeds) at 256 / 1,024 rays per origin (6 / 21 s of rays) with the
Fibonacci lattice of :func:`cosine_directions`, 0.0226 / 0.0169 with jittered n x n grids; the
Cycles-baked terms at their default erred 0.034 (1.9x). What a receiver gathers is the
radiosity of a diffuse surface, ``albedo / pi * E_direct``, linear over each triangle between
its corners' exact values (a shadow edge inside a triangle is blurred over it; the receivers
see it from afar, so it mostly averages out).

Shapes: ``G`` ray origins (one per distinct position and normal of the corners), ``C`` face
corners of every rendered mesh (the emitters; their back sides are columns ``C..2C-1`` of
``K``), ``V`` receivers, ``R1`` regions (0 fixed at its own colours, 1..R editable at albedo
1), ``S`` light directions. Irradiance is per unit normal irradiance of the light, as in
:mod:`.ptt`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Rays per origin of the default bake. Measured on the demo room through the whole default bake
#: (128 one-bounce directions with the receiver transfer, the second bounce composed; 7
#: held-out suns): relative error of E 0.0174 / 0.0167 / 0.0165 at 256 / 512 / 1,024 rays
#: (0.97x / 0.93x / 0.92x the noise floor) for 7.6 / 12.7 / 27.3 s of rays and 45.5 / 53.9 /
#: 66.9 MiB of tensors: past 512 the rays buy little.
DEFAULT_RAYS = 512
#: The fractional golden ratio: the second coordinate of the Fibonacci lattice.
_GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0
#: One stored transfer entry: ray origin, column of ``K`` (corner, or C + corner for a back
#: side) and weight (the fraction of the origin's rays, barycentrically split).
ENTRY = np.dtype([("origin", "<i4"), ("column", "<i4"), ("weight", "<f4")])


def cosine_directions(normals: np.ndarray, count: int, shifts: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions (B, count, 3) about each unit normal (B, 3).

    A Fibonacci lattice of ``count`` points in the unit square (``((i + 0.5) / n, i phi mod
    1)``: low discrepancy for any count) shifted by each origin's ``shifts`` (B, 2) in [0, 1)
    (a Cranley-Patterson rotation: every origin an unbiased, stratified estimate) and mapped
    to the hemisphere by Malley's method (uniform on the disc, lifted), so each ray carries the
    same weight ``pi / count`` of a cosine-weighted integral."""
    n = np.asarray(normals, np.float64)
    i = np.arange(int(count))
    base = np.stack([(i + 0.5) / count, (i * _GOLDEN) % 1.0], axis=1)          # (N, 2)
    u = (base[None] + np.asarray(shifts, np.float64)[:, None, :]) % 1.0         # (B, N, 2)
    r, phi = np.sqrt(u[..., 0]), 2.0 * np.pi * u[..., 1]
    local = np.stack([r * np.cos(phi), r * np.sin(phi),
                      np.sqrt(np.maximum(0.0, 1.0 - u[..., 0]))], axis=-1)
    helper = np.where(np.abs(n[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    return (local[..., 0:1] * t1[:, None] + local[..., 1:2] * t2[:, None]
            + local[..., 2:3] * n[:, None])


def hit_entries(origin: np.ndarray, corners: np.ndarray, bary: np.ndarray, front: np.ndarray,
                n_corners: int, rays: int) -> np.ndarray:
    """The transfer entries (:data:`ENTRY`, duplicates summed) of a block of ray hits.

    origin (M,) the ray's origin index; corners (M, 3) the hit triangle's face corners;
    bary (M, 3) the hit's barycentric weights; front (M,) bool, the ray met the triangle's
    front side (else its corners' back-side columns ``n_corners + corner``); ``rays`` per
    origin (each ray weighs ``1 / rays``). Rays that hit nothing are not passed."""
    col = np.asarray(corners, np.int64) + np.where(front, 0, n_corners)[:, None]
    key = np.repeat(np.asarray(origin, np.int64), 3) * (2 * n_corners) + col.ravel()
    w = np.asarray(bary, np.float64).ravel() / float(rays)
    uniq, inv = np.unique(key, return_inverse=True)
    out = np.empty(len(uniq), ENTRY)
    out["origin"], out["column"] = uniq // (2 * n_corners), uniq % (2 * n_corners)
    out["weight"] = np.bincount(inv.ravel(), weights=w, minlength=len(uniq))
    return out


def transfer_matrix(entries, n_origins: int, n_corners: int):
    """Sparse ``K`` (G, 2C) float64 CSR from blocks of :func:`hit_entries`: row ``g`` is the
    cosine-weighted fraction of origin ``g``'s hemisphere that each corner's side covers (a row
    sums to at most 1: the rest saw the sky)."""
    from scipy import sparse

    e = np.concatenate(list(entries)) if len(entries) else np.empty(0, ENTRY)
    return sparse.csr_matrix((e["weight"].astype(np.float64),
                              (e["origin"].astype(np.int64), e["column"].astype(np.int64))),
                             shape=(n_origins, 2 * n_corners))


@dataclass
class GatheredTransfer:
    """The gathered transfer of a scene and how its corners and receivers map onto it.

    Attributes
    ----------
    K : scipy.sparse.csr_matrix (G, 2C) float64
        :func:`transfer_matrix`.
    corner_origin : (C,) int64
        The ray origin of each face corner (its light is that origin's).
    corner_region : (C,) int
        Region of each corner's face (0 fixed, 1..R editable).
    corner_albedo : (C, 3) float64
        Diffuse colour each corner reflects with: 1 on editable regions (their colour is the
        run-time coefficient), the material's own on fixed ones.
    receivers : scipy.sparse.csr_matrix (V, C)
        Each receiver's mean over its corners (per vertex) or its corner (per face corner).
    regions : int
        R1, the number of regions with the fixed one.
    """

    K: object
    corner_origin: np.ndarray
    corner_region: np.ndarray
    corner_albedo: np.ndarray
    receivers: object
    regions: int

    def __post_init__(self):
        C = len(self.corner_origin)
        if (self.K.shape[1] != 2 * C or self.corner_region.shape != (C,)
                or self.corner_albedo.shape != (C, 3) or self.receivers.shape[1] != C
                or (C and int(self.corner_origin.max()) >= self.K.shape[0])):
            raise ValueError("the gathered transfer's arrays do not fit together")
        K = self.K.tocsc()
        # per region: its front and back columns (the light a region reflects off either side)
        self._K = []
        for r in range(self.regions):
            cols = np.nonzero(np.concatenate([self.corner_region == r] * 2))[0]
            self._K.append((cols, K[:, cols].tocsr()))

    @property
    def corners(self) -> int:
        return len(self.corner_origin)

    def back_sides(self) -> np.ndarray:
        """(C,) bool: corners whose back side some ray hit (their back-side direct light is
        needed; elsewhere it multiplies nothing)."""
        return np.asarray(abs(self.K[:, self.corners:]).sum(axis=0)).ravel() > 0

    def sky_fraction(self) -> float:
        """Mean over the origins of the share of rays that hit nothing (escaped to the sky)."""
        return float(1.0 - np.asarray(self.K.sum(axis=1)).mean()) if self.K.shape[0] else 0.0

    def _gather(self, r: int, values: np.ndarray) -> np.ndarray:
        """Irradiance (C, M) at every corner from region ``r``'s radiosity ``values`` (2C, M)
        (front then back columns; albedo x irradiance, so the cosine-weighted mean is E)."""
        cols, Kr = self._K[r]
        return np.asarray(Kr @ values[cols])[self.corner_origin]

    def one_bounce_corners(self, direct: np.ndarray, direct_back: np.ndarray | None = None
                           ) -> np.ndarray:
        """One-bounce irradiance (S, 3, R1, C) float64 at every corner: ``[s, c, r, j]`` is the
        light of direction ``s`` reflected once off region ``r`` (at albedo 1 on an editable
        region) arriving at corner ``j``, from the direct term ``direct`` (S, C) (visibility x
        cosine at each corner's front side) and ``direct_back`` (S, C) at the back sides (None:
        dark)."""
        D = np.asarray(direct, np.float64)
        S, C = D.shape
        Db = np.zeros_like(D) if direct_back is None else np.asarray(direct_back, np.float64)
        both = np.concatenate([D, Db], axis=1).T                            # (2C, S)
        alb = np.concatenate([self.corner_albedo] * 2)                      # (2C, 3)
        out = np.zeros((S, 3, self.regions, C))
        for r in range(self.regions):
            cols = self._K[r][0]
            if not len(cols):
                continue
            a = alb[cols]
            if np.allclose(a, a[:, :1]):       # grey (white) sources: one product for RGB
                g = self._gather(r, both * alb[:, :1])
                out[:, :, r] = g.T[:, None, :]
            else:
                g = self._gather(r, np.concatenate([both * alb[:, c:c + 1] for c in range(3)],
                                                   axis=1))
                out[:, :, r] = g.T.reshape(3, S, C).transpose(1, 0, 2)
        return out

    def two_bounce_corners(self, one: np.ndarray) -> np.ndarray:
        """Two-bounce irradiance (S, 3, R1, R1, C) at every corner from the one-bounce light
        ``one`` (S, 3, R1, C) (:meth:`one_bounce_corners`): ``[s, c, r1, r2, j]`` is the light
        off ``r1`` reflected once more off ``r2``'s front sides (the back sides' one-bounce
        light is not gathered: their second bounce is left out)."""
        S, _, R1, C = one.shape
        out = np.zeros((S, 3, R1, R1, C))
        for r2 in range(R1):
            cols = self._K[r2][0]
            front = cols[cols < C]
            if not len(front):
                continue
            src = np.zeros((2 * C, 3, R1, S))
            src[front] = (np.asarray(one, np.float64)[..., front].transpose(3, 1, 2, 0)
                          * self.corner_albedo[front][:, :, None, None])
            g = self._gather(r2, src.reshape(2 * C, -1)).reshape(C, 3, R1, S)
            out[:, :, :, r2] = g.transpose(3, 1, 2, 0)
        return out

    def to_receivers(self, corner_values: np.ndarray) -> np.ndarray:
        """``corner_values`` (..., C) -> (..., V) float32 through :attr:`receivers`."""
        flat = np.asarray(corner_values, np.float64).reshape(-1, self.corners)
        return np.asarray(self.receivers @ flat.T).T.reshape(
            *corner_values.shape[:-1], -1).astype(np.float32)

    def receiver_transfer(self, source_albedo: np.ndarray, direct_one: np.ndarray,
                          positions: np.ndarray | None = None,
                          radius: float | None = None) -> "ReceiverTransfer":
        """The transfer from the receivers' own direct light to their one-bounce light (front
        sides; the receivers that are not emitters of a region give it nothing), for
        :meth:`ReceiverTransfer.one_bounce_fix`. ``source_albedo`` (V, 3): each receiver's
        diffuse colour as a source (1 on editable regions); ``direct_one`` (S1, V): the
        receivers' direct term at the one-bounce directions the tables were made from. With
        ``positions`` (V, 3) metres and ``radius``: only the pairs of receivers closer than
        that (:data:`NEAR_FRACTION`)."""
        from scipy import sparse

        C = self.corners
        Q = (self.receivers.T != 0).astype(np.float64).tocsr()     # (C, V): corner -> receiver
        mats = []
        for r in range(self.regions):
            cols, Kr = self._K[r]
            front = cols < C
            A = (Kr[:, np.nonzero(front)[0]] @ Q[cols[front]]).tocsr()   # (G, V)
            mats.append(self.receivers @ A[self.corner_origin])              # (V, V)
        M = sparse.vstack(mats).tocoo()
        if positions is not None and radius is not None:
            pos = np.asarray(positions, np.float64)
            V = len(pos)
            near = np.linalg.norm(pos[M.row % V] - pos[M.col], axis=1) < radius
            M = sparse.coo_matrix((M.data[near], (M.row[near], M.col[near])), shape=M.shape)
        M = M.tocsc()
        M.eliminate_zeros()
        return ReceiverTransfer(sparse.csc_matrix(M, dtype=np.float32),
                                np.asarray(direct_one, np.float16),
                                np.asarray(source_albedo, np.float32))


#: A receiver's direct light is corrected where the one-bounce tables' blend of it is more than
#: this far (per unit normal irradiance) from the exact value (:meth:`ReceiverTransfer.one_bounce_fix`).
FIX_THRESHOLD = 1e-2
#: The receiver transfer keeps the pairs of receivers closer than this fraction of the
#: receivers' bounding-box diagonal. A blend smears a shadow edge into a band of part-lit
#: receivers whose lit area is about the exact one's, so seen from afar the difference cancels;
#: near it (a room's corner next to the shadowed wall) it does not. Measured on the demo room
#: (diagonal 3.46 m; 7 held-out suns, error of E): every pair 0.0167, within 0.69 m (0.2 of the
#: diagonal) 0.0172 (13 % of the entries), 0.35 m (0.1) 0.0177 (2.3 %), 0.15 m 0.0195, none
#: 0.0207; at 13K vertices every pair took 69 MiB and 11.6 ms of a 30 ms update, 0.2 of the
#: diagonal 17.6 MiB and 4.7 ms.
NEAR_FRACTION = 0.1


@dataclass
class ReceiverTransfer:
    """The gathered transfer between the receivers, which makes a sun's one-bounce light exact.

    The one-bounce tables are the transfer applied to the direct light at the baked
    directions, so blending them at a sun between those directions is the transfer applied to
    the *blended* direct light. That is wrong where a shadow edge lies between the directions:
    at such a receiver (a wall's vertex a shadow passes) the blend is part lit, the sun lights
    it fully or not at all. Near a corner of a room a receiver sees the next wall's vertices at
    grazing range, so the one-bounce light there changes steeply as an edge sweeps by (measured
    on the test room: a 0.25-degree turn of the sun moved the whole one-bounce term by 22 %, a
    row of wall vertices coming into the sun). The runtime knows the exact direct light at the
    receivers (a shadow ray where the baked directions disagree, :mod:`..operators.base.direct_rays`),
    so adding the transfer of the difference makes the blend exact at the receivers' resolution:
    a sparse product over the few receivers where the difference is not small. Measured on the
    demo room (512 rays, 7 held-out suns, the one-bounce part's error over the norm of E):
    blended from 128 / 400 directions 0.0194 / 0.0127, with the fix 0.0085 / 0.0085, the same as
    evaluating the transfer exactly at each sun (0.0085).

    Attributes
    ----------
    matrix : scipy.sparse.csc_matrix (R1 V, V) float32
        Row ``r V + v``, column ``u``: irradiance at receiver ``v`` per unit of albedo x
        irradiance at receiver ``u``'s corners of region ``r`` (the regions stacked: one
        column slice serves them all).
    direct_one : (S1, V) float16
        The receivers' direct term (visibility x cosine) at the one-bounce directions.
    source_albedo : (V, 3) float32
        Each receiver's colour as a source (1 on editable regions: the coefficient is the edit).
    """

    matrix: object
    direct_one: np.ndarray
    source_albedo: np.ndarray

    @property
    def regions(self) -> int:
        return self.matrix.shape[0] // max(self.matrix.shape[1], 1)

    @property
    def nbytes(self) -> int:
        m = self.matrix
        return int(m.data.nbytes + m.indices.nbytes + m.indptr.nbytes
                   + self.direct_one.nbytes + self.source_albedo.nbytes)

    def one_bounce_fix(self, direct: np.ndarray, index: np.ndarray, weights: np.ndarray,
                       threshold: float = FIX_THRESHOLD, into: np.ndarray | None = None,
                       scale=None) -> tuple:
        """What the one-bounce light (3, R1, V) float32, per unit normal irradiance, gains at
        a sun whose exact direct term is ``direct`` (V,) and whose blend over the one-bounce
        directions is ``index`` (K,) / ``weights`` (K,); and how many receivers were
        corrected (those whose blended direct light is more than ``threshold`` off). With
        ``into`` (3, R1, V) the gain times ``scale`` (3,) is added to it in place (returned)
        instead: only the receivers it touches are written."""
        d = np.asarray(direct, np.float32) - (np.asarray(weights, np.float32)
                                              @ self.direct_one[index].astype(np.float32))
        cols = np.nonzero(np.abs(d) > threshold)[0]
        V, R1 = len(d), self.regions
        out = np.zeros((3, R1, V), np.float32) if into is None else into
        if not len(cols):
            return out, 0
        scale = np.ones(3, np.float32) if scale is None else np.asarray(scale, np.float32)
        src = self.source_albedo[cols] * (d[cols, None] * scale[None, :])   # (n, 3)
        out += np.asarray(self.matrix[:, cols] @ src).T.reshape(3, R1, V)
        return out, len(cols)
