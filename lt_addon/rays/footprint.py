"""A texel's whole footprint, as a converged Cycles bake sees it (bpy-free).

One shading point per texel is exactly a 1-spp Cycles bake: its first sample is the texel centre.
Every further sample of Cycles' bake jitters the point within the texel
(``bake_jitter_barycentric`` in ``kernel/integrator/init_from_bake.h``, Blender 4.2-5.x): the
centre's barycentric coordinates move by ``(r - 0.5)`` times the differentials Blender computed
for the texel (``bake_differentials`` in ``render/intern/bake.cc``), and a point that falls
outside the centre's triangle is drawn again, up to 10 times, then left at the centre. The
jitter spans a box around the centre, in the centre's triangle only (the bake never moves to a
neighbouring triangle), whose side depends on the Blender release (:func:`jitter_box`): half a
texel up to 5.2.0 (Blender's differentials were half the barycentric derivative), a whole texel
from 5.2.1.

A converged bake is therefore, per texel, the mean over the part of that box inside the triangle
(fraction ``p``), mixed with the centre by the chance ``(1 - p)^10`` that all 10 draws fell
outside. :class:`Footprint` computes it with a stratified pattern over the box (:func:`offsets`,
shifted per texel: :func:`texel_shift`), adaptively: a texel is refined for a direction only
where its centre's value (lit or not) differs from one of its four neighbours' -- a shadow edge
or the terminator passes within a texel of it -- or where it crosses the edge of a triangle
thinner than a texel (:meth:`Footprint.thin`); elsewhere visibility is one value over the box
and the centre already is the mean (flat faces: the cosine is constant over a triangle; smooth
ones vary by the normal's change over the box, not refined). Shadows narrower than a texel that
fall between texel centres on wide triangles are missed. A thin texel on a smooth face whose
neighbours agree with it takes its footprint's mean normal instead of rays
(:meth:`Footprint.linear_means`: the cosine is linear in the normal), where the footprint's
normals agree (:data:`COHERENT`); sub-samples prepared for one chunk of directions are kept for
the next (:meth:`Footprint.prepare`).

Measured against Cycles' 256-spp bake of a hard sun (a flat-shaded brick relief, 64^2, planar
UVs, tests/blender/test_footprint.py) and the costs: docs/bench/2026-transport-log.md
"2026-12-06: texel footprints" and "2026-12-06: Blender 5.2.1's whole-texel jitter".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Side of Cycles' jitter box in texels up to Blender 5.2.0 (Blender's bake differentials: half
#: the barycentric derivative) and from 5.2.1 (the whole derivative), measured 2026-12-06 on each
#: release's bake of a step in an emission (a 16^2 plane, 1024 spp: the share of the box past
#: the step; 4.2.13, 4.5.15, 5.0.1, 5.1.2, 5.2.0: 0.502; 5.2.1, 5.2.2, 5.2.3, 5.3.0: 0.999;
#: tests/blender/test_footprint.py checks the running Blender's).
BOX = 0.5
BOX_FROM_5_2_1 = 1.0
WHOLE_TEXEL_FROM = (5, 2, 1)
#: Sub-samples of a refined texel and the generator of their rank-1 lattice over the box:
#: sample i at ((i + 1/2) / N, ((i * K) mod N + 1/2) / N), shifted per texel (:func:`texel_shift`).
#: One lattice for every texel errs alike on every texel of a repeated pattern: 16 rays with
#: K = 7 were 1.01x Cycles' own 16-spp distance from its 1024-spp bake at worst over 12 suns on
#: a brick relief at 128^2 with the half-texel box (an earlier set of suns), but 1.83x on the
#: relief at 64^2 and 3.17x at 128^2 under the whole-texel box (a lit sliver along each brick's
#: top edge held one of the 9 sub-samples inside in every such texel). Shifted per texel, that
#: error is noise, about Cycles' own 16 samples': mean 0.98x / 0.91x, worst 1.73x / 1.19x (half /
#: whole box, 12 suns at 128^2). The 34-point Fibonacci lattice (K = 21) halves it (worst 0.51x
#: / 0.66x) for about twice the footprint's rays and time (1.7-2.1x the direct stage on the
#: smooth demo scenes, whose sub-samples are shading points of their own). Measured 2026-12-06
#: (benchmarks/bench_footprint.py; the log's "Blender 5.2.1's whole-texel jitter").
SAMPLES = 16
LATTICE = 7
#: Cycles' redraws of a jitter that fell outside the triangle before it keeps the centre.
TRIES = 10
#: The lattice ``(n, k)`` of the horizons' footprint (:meth:`Footprint.samples`; the
#: horizon map's edge spread, :mod:`..transport.horizon_map`): 8 sub-samples, the Fibonacci
#: lattice (8, 3). On the gallery's relief at 128^2 (direct light against the 16-sample
#: footprint of rays, 2026-12-06): the centre's horizons 0.127 / 0.109 at 3 / 8 degrees under a
#: 0.526-degree Sun, with 5 sub-samples 0.071 / 0.065, 8 0.045 / 0.044, 16 0.031 / 0.027; the
#: horizons' rays 2.6x, 4.1x and 9.6x the centre's.
HORIZON_LATTICE = (8, 3)
#: Triangles narrower than this many texels (UV inradius) are refined wherever the jitter box
#: crosses their edges, whatever the neighbours say (:meth:`Footprint.thin`), if they hold at
#: least THIN_SHARE of the box: a triangle much smaller than a texel holds a sliver of it, where
#: Cycles' jitter barely moves (a dense displaced relief at 128^2 had every texel "thin": the
#: direct stage refined them all, at every direction).
THIN = 1.0
THIN_SHARE = 0.25
#: Thin smooth texels take :meth:`Footprint.linear_means` (no rays) only where their
#: sub-samples' normals agree this well: the weighted mean normal's length over the weights'
#: sum (1: all parallel; 0.9995: two equal halves 3.6 degrees apart).
COHERENT = 0.9995
#: Sub-samples of smooth (or touching) texels :meth:`Footprint.prepare` makes at most for a
#: chunk of directions (about 200 bytes each).
PREPARED_ROWS = 1 << 21
#: Memory for the flat texels' sub-sample positions, kept across directions (16 samples x 16
#: bytes + 4 a texel: about a million texels); texels past it are set up every direction.
CACHE_BYTES = 256 << 20


def jitter_box(version) -> float:
    """The side in texels of Cycles' bake jitter box in Blender ``version`` (a tuple such as
    ``bpy.app.version``): :data:`BOX` before 5.2.1, :data:`BOX_FROM_5_2_1` from it."""
    return BOX_FROM_5_2_1 if tuple(version)[:3] >= WHOLE_TEXEL_FROM else BOX


def texel_shift(texel) -> np.ndarray:
    """(M, 2) a fixed shift in [0, 1)^2 of the sub-sample lattice for each texel index
    ``texel`` (M,) (integer hashes: the same texel gets the same shift in every tile, chunk
    and run)."""
    t = np.asarray(texel).astype(np.uint64)
    with np.errstate(over="ignore"):
        a = t * np.uint64(0x9E3779B97F4A7C15)
        b = (t + np.uint64(0x632BE59BD9B4E019)) * np.uint64(0xC2B2AE3D27D4EB4F)
    return np.stack([a >> np.uint64(40), b >> np.uint64(40)], axis=1) / float(1 << 24)


def offsets(n: int | None = None, k: int | None = None, box: float = BOX,
            shift=None) -> np.ndarray:
    """Sub-sample offsets from the texel centre in texels: the rank-1 lattice (:data:`SAMPLES`,
    :data:`LATTICE` by default) over a jitter box of side ``box``; (n, 2), or (M, n, 2) with
    each of M texels' ``shift`` (M, 2) (:func:`texel_shift`) added modulo the box."""
    n = SAMPLES if n is None else int(n)
    k = LATTICE if k is None else int(k)
    i = np.arange(n)
    base = np.stack([(i + 0.5) / n, ((i * k) % n + 0.5) / n], axis=1)
    if shift is not None:
        base = np.mod(base[None] + np.asarray(shift, np.float64)[:, None, :] - 0.5 / n, 1.0)
    return (base - 0.5) * float(box)


def jitters(det) -> np.ndarray:
    """Whether Cycles jitters the bake over UV triangles whose ``det`` (twice the UV area, in
    texels^2) is given: Blender leaves the differentials 0 (no jitter: the centre alone) for a
    triangle of no area (``|det| <= FLT_EPSILON``)."""
    return np.abs(np.asarray(det, np.float64)) > np.finfo(np.float32).eps


def on_triangle(uv, centre, off, resolution: int):
    """Cycles' bake jitter over M texels' centres ``centre`` (M, 2) on their UV triangles
    ``uv`` (M, 3, 2): which of the sub-samples at ``off`` (M, K, 2) or (K, 2) texels from the
    centre lie on the triangle (Cycles' strict test; none on a UV triangle of no area, where
    Blender leaves the differentials 0), their barycentrics, and the weights of a texel's
    mean: each sub-sample on the triangle ``each`` (M,) and the centre ``centre_w`` (M,) --
    Cycles redraws a jitter that fell off the triangle up to :data:`TRIES` times, then keeps
    the centre. Returns ``(inside (M, K), (b0, b1, b2) (M, K) each, each, centre_w)``."""
    uv = np.asarray(uv, np.float64)
    off = np.asarray(off, np.float64)
    q = np.asarray(centre, np.float64)[:, None, :] + off / float(resolution)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    area_ok = jitters(np.abs(det) * float(resolution) ** 2)
    safe = np.where(area_ok, det, 1.0)
    d = q - uv[:, None, 0]
    b1 = (d[..., 0] * e2[:, None, 1] - d[..., 1] * e2[:, None, 0]) / safe[:, None]
    b2 = (e1[:, None, 0] * d[..., 1] - e1[:, None, 1] * d[..., 0]) / safe[:, None]
    b0 = 1.0 - b1 - b2
    inside = (b0 > 0) & (b1 > 0) & (b2 > 0) & area_ok[:, None]   # Cycles' strict test
    k_in = inside.sum(axis=1)
    jittered = 1.0 - (1.0 - k_in / inside.shape[1]) ** TRIES      # a draw landed inside
    return inside, (b0, b1, b2), jittered / np.maximum(k_in, 1), 1.0 - jittered


def thin_area_share(uv, resolution: int) -> float:
    """The share of the UV map's area (``uv`` (T, 3, 2), 0..1) in triangles narrower than
    :data:`THIN` texels (UV inradius) at ``resolution``: where :meth:`Footprint.thin` refines a
    texel at every direction. Thin triangles appear at low resolutions, so a small bake of a
    dense mesh refines far more of its texels than a large one (the bake-time estimate picks
    its calibration sizes by it)."""
    uv = np.asarray(uv, np.float64).reshape(-1, 3, 2)
    if not len(uv):
        return 0.0
    e = np.stack([uv[:, 2] - uv[:, 1], uv[:, 0] - uv[:, 2], uv[:, 1] - uv[:, 0]], 1)
    length = np.linalg.norm(e, axis=2).sum(axis=1)
    area2 = np.abs(e[:, 2, 0] * (-e[:, 1, 1]) - e[:, 2, 1] * (-e[:, 1, 0]))
    total = area2.sum()
    if total <= 0:
        return 0.0
    inradius = area2 / np.maximum(length, 1e-30) * float(resolution)          # texels
    return float(area2[inradius < THIN].sum() / total)


def edges(texel, resolution: int, values) -> np.ndarray:
    """Indices of the points whose ``values`` (P,) (lit: > 0) differ from a covered grid
    neighbour's (left, right, below, above); ``texel`` (P,) row-major indices into
    ``resolution^2``. On the image grid: no per-point neighbour table is kept (at 4096^2 it
    would be 256 MB)."""
    R = int(resolution)
    img = np.full((R, R), -1, np.int8)
    img.reshape(-1)[np.asarray(texel)] = np.asarray(values) > 0
    diff = np.zeros((R, R), bool)
    for a, b in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                 ((slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
        x, y = img[a], img[b]
        d = (x >= 0) & (y >= 0) & (x != y)
        diff[a] |= d
        diff[b] |= d
    return np.nonzero(diff.reshape(-1)[np.asarray(texel)])[0]


@dataclass
class Footprint:
    """What refining a texture bake's points needs: the mesh, its UV triangles and each point's
    triangle, barycentric point and grid neighbours.

    Attributes
    ----------
    vertices : (V, 3) world;  triangles : (T, 3);  corner_normals : (T, 3, 3);  smooth : (T,)
    bool;  cutoff, mirrored, bump, correction : as :func:`.shading.shading_points` takes them;
    uv : (T, 3, 2) the bake's UV map;  resolution : texels a side;  texel : (P,) each point's
    texel;  triangle : (P,);  bary : (P, 3) (the texel samples' own arrays, not copies);
    box : the jitter box's side in texels (:func:`jitter_box` of the Blender that bakes).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    corner_normals: np.ndarray
    smooth: np.ndarray
    cutoff: float
    mirrored: bool
    bump: str
    correction: np.ndarray
    uv: np.ndarray
    resolution: int
    texel: np.ndarray
    triangle: np.ndarray
    bary: np.ndarray
    box: float = BOX
    refined: int = 0        # texel-directions refined so far
    rays: int = 0           # sub-sample rays cast so far
    linear: int = 0         # texel-directions of thin smooth texels taken without rays

    def subset(self, rows) -> "Footprint":
        """The footprint of the points ``rows`` alone (the same mesh; their texels'
        neighbours outside ``rows`` count as not covered): a tile of texels refines as the
        whole texture does inside it."""
        rows = np.asarray(rows, np.int64)
        return Footprint(self.vertices, self.triangles, self.corner_normals, self.smooth,
                         self.cutoff, self.mirrored, self.bump, self.correction, self.uv,
                         self.resolution, self.texel[rows], self.triangle[rows],
                         self.bary[rows], self.box)

    def edges(self, values, points=None) -> np.ndarray:
        """The points to refine at a direction whose centre values are ``values`` (P,):
        :func:`edges` of this bake's points, and the :meth:`thin` ones -- but for the thin
        texels :meth:`linear_means` takes (smooth faces; ``points`` given), which rays refine
        only where :func:`edges` flags them."""
        found = edges(self.texel, self.resolution, values)
        thin = self.thin()
        if points is not None and len(thin):
            if getattr(self, "_thin_rays", None) is None:     # the same every direction
                lin = self._linear(points)[0]
                self._thin_rays = (np.setdiff1d(thin, lin, assume_unique=True) if len(lin)
                                   else thin)
            thin = self._thin_rays
        return np.union1d(found, thin) if len(thin) else found

    def _linear(self, points):
        """``(idx, centre_weight, mean_normal)`` of the thin texels on smooth faces (no normal
        map, not touching another object): per texel the centre's weight and the weighted sum
        of its sub-samples' shading normals ``sum_i w_i Ns_i`` (M, 3), made once."""
        if getattr(self, "_lin", None) is None:
            thin = self.thin()
            ok = np.asarray(self.smooth, bool)[self.triangle[thin]]
            mapped = points.mapped()
            if mapped is not None and len(mapped):
                ok &= ~np.isin(thin, mapped)
            if points.normal_set is not None:
                ok &= points.normal_set.index(thin) < 0
            if points.contact is not None:
                ok &= ~points.contact.touching[thin]
            idx = thin[ok]
            nbar = np.zeros((len(idx), 3))
            cw = np.ones(len(idx))
            wsum = np.zeros(len(idx))
            for a in range(0, len(idx), PREPARED_ROWS // SAMPLES):
                part = idx[a:a + PREPARED_ROWS // SAMPLES]
                owner, sub, weight, centre_w = self._sub_points(points, part)
                for k in range(3):
                    nbar[a:a + len(part), k] = np.bincount(
                        owner, weights=weight * sub.Ns[:, k], minlength=len(part))
                wsum[a:a + len(part)] = np.bincount(owner, weights=weight, minlength=len(part))
                cw[a:a + len(part)] = centre_w
            # only where the footprint's normals agree (a gently curved patch); where they
            # spread (a crease, a fold) a shadow can start inside the texel unseen by the
            # neighbours, and rays refine it as before
            coherent = np.linalg.norm(nbar, axis=1) >= COHERENT * np.maximum(wsum, 1e-30)
            self._lin = (idx[coherent], cw[coherent], nbar[coherent])
        return self._lin

    def linear_means(self, points, values, L, skip) -> None:
        """The footprint means of the thin smooth texels (:meth:`_linear`) that ``skip`` (the
        points rays refine at this direction) leaves, into ``values`` (P,) in place: the centre's
        share of its value plus ``max(sum_i w_i Ns_i . L, 0) / pi`` where the centre is lit.
        There the centre and its four neighbours are all lit or all dark (:func:`edges` flags
        the rest), so the sub-samples are taken to share the centre's visibility and to face
        the sun together -- the cosine of a smooth face is linear in its normal -- and no ray is
        cast (the clipped jitter box's mean differs from the centre's value there: smooth demo
        bumps at 128^2, the centre alone 3.8-5x Cycles' 16-spp distance)."""
        idx, cw, nbar = self._linear(points)
        if not len(idx):
            return
        # (a mask over the points, not a sort of the thin texels, every direction)
        refined = np.zeros(len(self.texel), bool)
        refined[np.asarray(skip, np.int64)] = True
        keep = ~refined[idx]
        i, cw, nbar = idx[keep], cw[keep], nbar[keep]
        centre = np.asarray(values[i], np.float64)
        lit = centre > 0
        values[i] = cw * centre + np.where(lit, np.maximum(nbar @ np.asarray(L, np.float64),
                                                           0.0) / np.pi, 0.0)
        self.linear += int(len(i))

    def thin(self) -> np.ndarray:
        """Indices of the points whose jitter box crosses an edge of a triangle narrower than
        :data:`THIN` texels (UV inradius): a lit or shadowed sliver there can lie between the
        texel centres, where :func:`edges` cannot see it (a brick relief at 64^2, triangles
        1.3 texels wide: 0.19 from Cycles' converged bake at 2 degrees against 0.038 with
        them). Made once."""
        if getattr(self, "_thin", None) is None:
            R = float(self.resolution)
            out = []
            for a in range(0, len(self.texel), 1 << 20):
                tri = self.triangle[a:a + (1 << 20)]
                uv = self.uv[tri] * R                                       # texels
                e = np.stack([uv[:, 2] - uv[:, 1], uv[:, 0] - uv[:, 2], uv[:, 1] - uv[:, 0]], 1)
                length = np.linalg.norm(e, axis=2)                            # (n, 3)
                area2 = np.abs(e[:, 2, 0] * (-e[:, 1, 1]) - e[:, 2, 1] * (-e[:, 1, 0]))
                inradius = area2 / np.maximum(length.sum(axis=1), 1e-30)
                # the centre's distance to each edge: its barycentric times the height
                dist = self.bary[a:a + len(tri)] * area2[:, None] / np.maximum(length, 1e-30)
                crosses = dist.min(axis=1) < self.box / np.sqrt(2.0)
                cand = np.nonzero((inradius < THIN) & crosses)[0]
                if len(cand):   # ... and covers enough of the box for a sliver to matter
                    owner = self.samples(cand + a)[0]
                    share = np.bincount(owner, minlength=len(cand)) / SAMPLES
                    cand = cand[share >= THIN_SHARE]
                out.append(cand + a)
            self._thin = np.concatenate(out) if out else np.zeros(0, np.int64)
        return self._thin

    def samples(self, idx, lattice=None):
        """The sub-samples of points ``idx`` (M,): their (N,) owner among ``idx``, (N,)
        triangle, (N, 3) barycentrics inside the triangle and (N,) weight, with the centre's
        own weight (M,) -- a point's value is ``centre_weight * centre + sum(weight * sub)``.
        ``lattice``: ``(n, k)`` of another rank-1 lattice than :data:`SAMPLES`,
        :data:`LATTICE` (the horizons' :data:`HORIZON_LATTICE`)."""
        idx = np.asarray(idx, np.int64)
        tri = self.triangle[idx]
        uv = self.uv[tri]                                            # (M, 3, 2)
        c = np.einsum("mk,mkj->mj", self.bary[idx], uv)
        n, k = lattice if lattice is not None else (None, None)
        off = offsets(n, k, box=self.box, shift=texel_shift(self.texel[idx]))   # (M, K, 2)
        inside, (b0, b1, b2), each, centre_w = on_triangle(uv, c, off, self.resolution)
        owner, sub = np.nonzero(inside)
        bary = np.stack([b0[owner, sub], b1[owner, sub], b2[owner, sub]], axis=1)
        return owner, tri[owner], bary, each[owner], centre_w

    def _flat_cache(self, idx):
        """Slots (M,) of points ``idx`` (flat faces) in the sub-sample cache, filling the
        missing ones: per slot the :data:`SAMPLES` sub-sample positions (float32, world) and
        weights (0: outside the triangle) and the centre's weight. -1 where the cache is full
        (:data:`CACHE_BYTES`)."""
        if getattr(self, "_slot", None) is None:
            self._slot = np.full(len(self.texel), -1, np.int64)
            self._used = 0
            self._P = np.zeros((0, SAMPLES, 3), np.float32)
            self._W = np.zeros((0, SAMPLES), np.float32)
            self._C = np.zeros(0, np.float32)
        slot = self._slot[idx]
        new = idx[slot < 0]
        room = CACHE_BYTES // (SAMPLES * 16 + 4) - self._used
        new = new[:max(room, 0)]
        if len(new):
            owner, tri, bary, weight, centre_w = self.samples(new)
            need = self._used + len(new)
            if need > len(self._C):          # grow by doubling
                cap = max(need, 2 * len(self._C), 1024)
                for name in ("_P", "_W", "_C"):
                    old = getattr(self, name)
                    grown = np.zeros((cap,) + old.shape[1:], old.dtype)
                    grown[:len(old)] = old
                    setattr(self, name, grown)
            slots = self._used + np.arange(len(new))
            # the sub-sample's rank within its texel's inside samples
            first = np.searchsorted(owner, np.arange(len(new)))
            rank = np.arange(len(owner)) - first[owner]
            V = np.asarray(self.vertices, np.float64)
            P = np.einsum("nk,nkj->nj", bary, V[np.asarray(self.triangles)[tri]])
            self._P[slots[owner], rank] = P
            self._W[slots[owner], rank] = weight
            self._C[slots] = centre_w
            self._slot[new] = slots
            self._used = need
            slot = self._slot[idx]
        return slot

    def _sub_points(self, points, idx, lattice=None):
        """The sub-samples of points ``idx`` (M,) as shading points of their own: ``(owner (N,)
        among idx, ShadingPoints (N), weight (N,), centre weight (M,))``, each made as the
        centres were (normals, terminator lift), with its texel's closure normal where a normal
        map changes it and its texel's contact with other objects. ``lattice``: as
        :meth:`samples`."""
        from .shading import shading_points

        owner, tri, bary, weight, centre_w = self.samples(idx, lattice)
        sub = shading_points(self.vertices, self.triangles, self.corner_normals, self.smooth,
                             tri, bary, cutoff=self.cutoff, mirrored=self.mirrored,
                             bump=self.bump, correction=self.correction)
        sub.epsilon = points.epsilon
        of = idx[owner]
        mapped = points.mapped()
        if mapped is not None:        # a normal map: the texel's closure normal
            m = np.isin(of, mapped)
            if m.any():
                sub.Ns = sub.N.copy()
                sub.Ns[m] = points.Ns[of[m]]
        if points.normal_set is not None:   # sampled normals: the texel's, for every sub-sample
            sub.normal_set = points.normal_set.take(of)
        if points.contact is not None:
            sub.contact = points.contact.subset(of)
        return owner, sub, weight, centre_w

    def prepare(self, points, idx) -> None:
        """Make the sub-sample shading points of the points ``idx`` that :meth:`refine` does not
        take on its flat path (smooth faces, texels touching other objects) for the directions
        to come (a chunk's: the union of what they refine); :meth:`refine` then takes their rows
        instead of making them again for every direction (on the smooth bumps that set-up was
        2/3 of the direct stage). They are kept across chunks, as segments of at most
        :data:`PREPARED_ROWS` sub-samples in all, the oldest dropped first: a texel refined in
        one chunk is mostly refined in the next (its shadow edge moves little), and making them
        again every chunk was a third of the bumps' footprint time at 256^2."""
        idx = np.asarray(idx, np.int64)
        flat = ~np.asarray(self.smooth, bool)[self.triangle[idx]]
        if points.contact is not None:
            flat &= ~points.contact.touching[idx]
        idx = idx[~flat]
        if getattr(self, "_seg_of", None) is None:
            self._seg_of = np.full(len(self.texel), -1, np.int64)
            self._local = np.full(len(self.texel), -1, np.int64)
            self._segs, self._seg_rows, self._next_seg = {}, 0, 0
        new = idx[self._seg_of[idx] < 0][:PREPARED_ROWS // SAMPLES]
        if not len(new):
            return
        owner, sub, weight, centre_w = self._sub_points(points, new)
        # the oldest segments make room (their texels are made again when asked)
        while self._segs and self._seg_rows + len(owner) > PREPARED_ROWS:
            old = min(self._segs)
            seg = self._segs.pop(old)
            self._seg_of[seg["texels"]] = -1
            self._seg_rows -= seg["rows"]
        k = self._next_seg
        self._next_seg += 1
        self._seg_of[new] = k
        self._local[new] = np.arange(len(new))
        self._segs[k] = {"texels": new, "sub": sub, "weight": weight, "centre": centre_w,
                         "start": np.searchsorted(owner, np.arange(len(new) + 1)),
                         "rows": len(owner)}
        self._seg_rows += len(owner)

    def _prepared(self, idx) -> np.ndarray:
        """(M,) bool: which points ``idx`` :meth:`prepare` holds."""
        seg_of = getattr(self, "_seg_of", None)
        return np.zeros(len(idx), bool) if seg_of is None else seg_of[idx] >= 0

    def _refine_prepared(self, idx, L, centre, occluder, cosine_at, shadow_origins):
        """:meth:`refine` of points ``idx`` (all prepared) from the prepared rows, a segment
        at a time."""
        out = np.asarray(centre, np.float64).copy()
        seg_of = self._seg_of[idx]
        for k in np.unique(seg_of):
            at = np.nonzero(seg_of == k)[0]
            pr = self._segs[int(k)]
            slot = self._local[idx[at]]
            start, stop = pr["start"][slot], pr["start"][slot + 1]
            counts = stop - start
            owner = np.repeat(np.arange(len(at)), counts)
            rows = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) \
                + np.repeat(start, counts)
            part = pr["centre"][slot] * out[at]
            if len(rows):
                val = self._sub_values(pr["sub"], rows, cosine_at(pr["sub"], L, rows), L,
                                       occluder, shadow_origins)
                part = part + np.bincount(owner, weights=pr["weight"][rows] * val,
                                          minlength=len(at))
            out[at] = part
        return out

    def _sub_values(self, sub, rows, cos, L, occluder, shadow_origins) -> np.ndarray:
        """cosine x visibility / pi (len(rows),) of the sub-sample shading points ``rows`` of
        ``sub`` towards ``L``, given their cosines ``cos``: one shadow ray each where lit, and
        a contact ray where it touches another object (:mod:`.contact`)."""
        from . import contact as contact_rays

        lit = np.nonzero(cos > 0)[0]
        val = np.zeros(len(rows))
        if len(lit):
            r = rows[lit]
            origins = shadow_origins(sub, L, r)
            hit = occluder.occluded(origins, np.asarray(L, np.float32))
            if sub.contact is not None:
                near = np.nonzero(sub.contact.touching[r] & ~hit)[0]
                if len(near):
                    hit[near] = contact_rays.blocked(sub, r[near], L, origins[near])
            val[lit] = np.where(hit, 0.0, cos[lit] / np.pi)
            self.rays += len(lit)
        return val

    def refine(self, points, idx, L, centre, occluder, cosine, shadow_origins) -> np.ndarray:
        """The footprint means (M,) of points ``idx`` towards unit ``L`` (3,), given their
        centre values ``centre`` (M,) (cosine x visibility / pi): one shadow ray per
        sub-sample, its origin made as the centres' are. On a flat face a sub-sample shares its
        centre's normals and cosine (only its position moves: no lift, the same push; its
        positions are cached across directions); on a smooth one it is a shading point of its
        own (normal, terminator lift). Where a normal map changes the closure normal, the
        sub-samples take their texel's; where the texel touches another object's surface
        (:mod:`.contact`), they do too."""
        idx = np.asarray(idx, np.int64)
        L = np.asarray(L, np.float64)
        out = np.asarray(centre, np.float64).copy()
        flat = ~np.asarray(self.smooth, bool)[self.triangle[idx]]
        if points.contact is not None:       # (the general path has the contact rays)
            flat &= ~points.contact.touching[idx]
        slot = self._flat_cache(idx[flat]) if flat.any() else np.zeros(0, np.int64)
        fast = np.nonzero(flat)[0][slot >= 0]
        slot = slot[slot >= 0]
        if len(fast):
            i = idx[fast]
            sub_p = (points.subset(i) if points.mapped() is not None
                     or points.normal_set is not None else None)
            cos = (cosine(sub_p, L) if sub_p is not None
                   else np.maximum(points.Ns[i] @ L, 0.0))
            lit = np.nonzero(cos > 0)[0]
            val = np.zeros(len(fast))
            if len(lit):
                Ng = points.Ng[i[lit]]
                side = np.where(Ng @ L < 0, -1.0, 1.0)
                eps = points.epsilon * np.maximum(1.0, np.abs(points.P[i[lit]]).max(axis=1))
                push = ((eps * side)[:, None] * Ng).astype(np.float32)
                W = self._W[slot[lit]]                                   # (m, K)
                m, k = np.nonzero(W > 0)
                origins = self._P[slot[lit][m], k] + push[m]
                hit = occluder.occluded(origins, L.astype(np.float32))
                seen = np.bincount(m, weights=np.where(hit, 0.0, W[m, k]),
                                   minlength=len(lit))
                val[lit] = seen * cos[lit] / np.pi
                self.rays += len(m)
            out[fast] = self._C[slot] * out[fast] + val
        rest = np.setdiff1d(np.arange(len(idx)), fast, assume_unique=True)
        if len(rest):
            ready = rest[self._prepared(idx[rest])]
            if len(ready):
                from .shading import cosine_at

                out[ready] = self._refine_prepared(idx[ready], L, out[ready], occluder,
                                                   cosine_at, shadow_origins)
                rest = np.setdiff1d(rest, ready, assume_unique=True)
        if len(rest):
            out[rest] = self._refine_points(points, idx[rest], L, out[rest], occluder, cosine,
                                            shadow_origins)
        self.refined += len(idx)
        return out

    def _refine_points(self, points, idx, L, centre, occluder, cosine,
                       shadow_origins) -> np.ndarray:
        """:meth:`refine` by sub-sample shading points of their own (smooth faces, texels
        touching other objects, or past the cache)."""
        owner, sub, weight, centre_w = self._sub_points(points, idx)
        out = centre_w * np.asarray(centre, np.float64)
        if not len(owner):
            return out
        val = self._sub_values(sub, np.arange(len(owner)), cosine(sub, L), L, occluder,
                               shadow_origins)
        return out + np.bincount(owner, weights=weight * val, minlength=len(idx))
