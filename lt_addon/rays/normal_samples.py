"""Sub-texel shading normals of normal- and bump-mapped materials (bpy-free).

A converged Cycles bake averages each texel over its jitter box, and a normal or bump map can
change the closure normal within one texel (a Brick texture's mortar through a Bump node: the
normal tilts in a band a fraction of a texel wide). A single normal per texel -- Cycles' 1-spp
NORMAL bake, which samples the texel's centre -- is then the texel's centre, not the texel:
on the gallery's brick plane at 128^2 the centre's cosine was 0.10-0.11 from Cycles' 256-spp
direct bake at every elevation (the mortar lines missing), and so was Cycles' own 1-spp bake.

The cosine (with Cycles' bump terminator term) is not linear in the normal, so a mean normal
does not mend it: with the mean of 16 samples, 0.05 at 45 degrees, 0.36-0.52 at 3 degrees.
What does is the mean of the cosine over normals sampled across the box. Cycles' bake has no
per-sample output, and a NORMAL bake's seed does not move its 1-spp sample (measured: seeds
0-15 gave identical images), so the bpy layer bakes the normals at shifted texel centres
instead: a temporary copy of the bake's UV map moved by a sub-texel offset, one 1-spp NORMAL
bake per offset. The texture's resolution is unchanged, so Cycles' ray differentials (the
Bump node's finite differences) are the bake's own.

The offsets are the rank-1 Fibonacci lattice :data:`LATTICE` over Cycles' jitter box
(:func:`.footprint.jitter_box`). Measured 2026-12-07 on the gallery's brick plane alone at
128^2, bpy 5.0.1 (the cosine's mean against Cycles' 1024-spp direct bake of a 0.526-degree Sun
at 8 / 45 degrees; Cycles' 256-spp bake is 0.0020 / 0.0014 from it): the centre 0.106 / 0.104;
a regular 4x4 grid 0.069 / 0.053 (its rows alias with the mortar), 8x8 0.030 / 0.024; the
lattices (8, 3) 0.034 / 0.027, (13, 8) 0.023 / 0.015, (21, 13) 0.012 / 0.007, (34, 21)
0.011 / 0.007. 21 one-spp NORMAL bakes took 0.35 s at 128^2.

Only texels whose sampled normals differ (:data:`VARYING`) keep them (float16); the rest keep
their mean, as one normal did before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The sub-texel lattice ``(n, k)`` of the normals: n offsets, the k-th Fibonacci generator.
LATTICE = (21, 13)
#: Smaller lattices, in order, where :data:`LATTICE` would hold more than :data:`MEMORY`.
SMALLER = ((13, 8), (8, 5), (5, 3))
#: Memory for the sampled normals of all mapped objects together, at :data:`NORMAL_BYTES` each.
MEMORY = 512 << 20
#: Bytes a sampled normal holds: 6 (float16) while baked and kept, 4 for its weight (float32);
#: the cosines' terms are made a block at a time (:attr:`_Shared.BLOCK`).
NORMAL_BYTES = 12
#: A texel keeps its sampled normals where one of them is further than this from their mean
#: direction (1 - cos: 1e-4 is 0.8 degrees); elsewhere the mean's cosine is the samples' to
#: second order.
VARYING = 1e-4


def lattice_for(texels: int, memory: int = MEMORY) -> tuple:
    """The lattice ``(n, k)`` whose normals for ``texels`` texels (all mapped objects') fit
    ``memory`` (:data:`NORMAL_BYTES` each), or ``(1, 0)`` (the centre alone) where none does."""
    for n, k in (LATTICE,) + SMALLER:
        if (n + 1) * int(texels) * NORMAL_BYTES <= memory:
            return (n, k)
    return (1, 0)


def offsets(lattice, box: float) -> np.ndarray:
    """(n + 1, 2) offsets in texels from the texel centre: the centre itself (Cycles keeps it
    where its jitter keeps falling off the centre's triangle), then the lattice ``(n, k)`` over
    a jitter box of side ``box`` (sample i at ((i + 1/2) / n, ((i k) mod n + 1/2) / n) of the
    box); the centre alone for ``(1, 0)``."""
    n, k = int(lattice[0]), int(lattice[1])
    if n <= 1:
        return np.zeros((1, 2))
    i = np.arange(n)
    base = np.stack([(i + 0.5) / n, ((i * k) % n + 0.5) / n], axis=1)
    return np.vstack([np.zeros((1, 2)), (base - 0.5) * float(box)])


class Sampler:
    """Collects one object's sampled normals, offset by offset, into :class:`TexelNormals`.

    ``add(image)``: (R, R, 3) world unit normals of one offset (zeros where no texel was
    baked); the first image's covered texels are the ones kept. ``done(offsets)``: the result,
    given the (K, 2) offsets in texels the images were baked at (:func:`offsets`)."""

    def __init__(self, count: int):
        self.count, self.k = int(count), 0
        self.pixels = self.stack = self.sum = self.shape = None

    def add(self, image) -> None:
        img = np.asarray(image, np.float64)
        flat = img.reshape(-1, 3)
        if self.pixels is None:
            self.shape = img.shape
            self.pixels = np.nonzero(np.linalg.norm(flat, axis=1) > 0.5)[0]
            self.stack = np.empty((len(self.pixels), self.count, 3), np.float16)
            self.sum = np.zeros((len(self.pixels), 3))
        n = flat[self.pixels]
        bad = np.linalg.norm(n, axis=1) < 0.5     # an offset past the island and its margin
        if self.k and bad.any():                  # (the centre's normal stands in)
            n[bad] = self.stack[bad, 0].astype(np.float64)
        self.stack[:, self.k] = n
        if self.k or self.count == 1:             # (the mean is the lattice's)
            self.sum += n
        self.k += 1

    def done(self, offsets) -> "TexelNormals":
        """The texels' normals: their mean over the lattice (the centre's alone without one),
        and the samples of those whose normals spread further than :data:`VARYING`."""
        if self.k != self.count:
            raise ValueError(f"{self.k} of {self.count} offsets baked")
        mean = np.zeros(self.shape).reshape(-1, 3)
        Q = len(self.pixels)
        m = self.sum / np.maximum(np.linalg.norm(self.sum, axis=1, keepdims=True), 1e-30)
        mean[self.pixels] = m
        keep = []
        if self.count > 1:
            for a in range(0, Q, _Shared.BLOCK):     # (a block's float32 temporaries at a time)
                s = self.stack[a:a + _Shared.BLOCK].astype(np.float32)
                s /= np.maximum(np.linalg.norm(s, axis=2, keepdims=True), 1e-12)
                c = np.einsum("qkj,qj->qk", s, m[a:a + _Shared.BLOCK].astype(np.float32))
                keep.append(a + np.nonzero(1.0 - c.min(axis=1) > VARYING)[0])
        keep = np.concatenate(keep) if keep else np.zeros(0, np.int64)
        samples = self.stack if len(keep) == Q else np.ascontiguousarray(self.stack[keep])
        self.stack = None
        return TexelNormals(mean.reshape(self.shape), self.pixels[keep], samples, self.count,
                            np.asarray(offsets, np.float64).reshape(self.count, 2))


@dataclass
class TexelNormals:
    """One object's closure normals in world space: ``mean`` (R, R, 3) unit (zeros where no
    texel was baked), and the sampled normals (Q, K, 3) float16 of the ``pixels`` (Q,) (sorted
    row-major indices) where they differ; ``count``: K, the centre and the lattice's size;
    ``offsets`` (K, 2): where in its texel (in texels, from the centre) the k-th normal was
    baked: the bake's UV map was moved by the offset, so the normal is the surface's at the
    centre *minus* it."""

    mean: np.ndarray
    pixels: np.ndarray
    samples: np.ndarray
    count: int
    offsets: np.ndarray = None

    @property
    def shape(self):
        return self.mean.shape

    def normal_set(self, texel, N, correction=None, bump: str = "conty",
                   weigh=None) -> "NormalSet | None":
        """The :class:`NormalSet` of the points whose texels are ``texel`` (P,), with their
        smooth normals ``N`` (P, 3) and their materials' bump map ``correction`` (P,) bool
        (None: on), under Cycles' bump terminator term ``bump``; ``weigh``: a function of the
        points' indices (M,) giving their samples' (M, K) weights (:func:`weights`), asked a
        block at a time, or None (every texel wholly on its triangle: the lattice's samples
        alike, the centre none). None where no point's texel has sampled normals."""
        if not len(self.pixels):
            return None
        texel = np.asarray(texel, np.int64)
        pos = np.minimum(np.searchsorted(self.pixels, texel), len(self.pixels) - 1)
        hit = self.pixels[pos] == texel
        if not hit.any():
            return None
        rows = np.nonzero(hit)[0]
        corr = None if correction is None else np.asarray(correction, bool)[rows]
        at = pos[hit]
        whole = len(at) == len(self.pixels) and bool(np.all(at[1:] > at[:-1]))
        shared = _Shared(self.samples if whole else self.samples[at],
                         np.asarray(N, np.float64)[rows], corr, bump,
                         None if weigh is None else (lambda sel: weigh(rows[sel])))
        return NormalSet(rows, shared, np.arange(len(rows)))


def weights(uv_tri, uv_centre, offsets, resolution: int) -> np.ndarray:
    """(M, K) weights of M texels' K sampled normals in their means -- the centre's first,
    then the lattice's -- as Cycles' jitter weighs them (:func:`.footprint.on_triangle`: the
    samples on the centre's UV triangle ``uv_tri`` (M, 3, 2) share what the jitter gives them,
    the centre the rest). A sample was baked with the UV map moved by its offset, so it lies
    at ``uv_centre`` (M, 2) *minus* ``offsets`` (K, 2) texels."""
    from .footprint import on_triangle

    if len(offsets) == 1:                        # the centre alone
        return np.ones((len(uv_centre), 1))
    off = -np.asarray(offsets, np.float64)[1:]
    inside, _, each, centre_w = on_triangle(uv_tri, uv_centre, off, resolution)
    return np.concatenate([centre_w[:, None], inside * each[:, None]], axis=1)


#: Bytes a set may hold of the sun-independent terms of its cosines (the unit normals, their
#: cosine with the smooth normal, the masking's roughness: 21 bytes a normal); past them the
#: terms are made again a block at a time for every direction (measured on 7,273 texels x 22
#: normals: 9.4 ms a direction made again, 2.4 ms kept).
PRECOMPUTE_BYTES = 128 << 20
#: Bytes of cosines :class:`_Shared` keeps per set for the directions asked last (the direct
#: stage asks each direction of a chunk twice: its rows, then the footprints' refinement).
CACHE_BYTES = 64 << 20


class _Shared:
    """The sampled normals of a set's entries (Q, K, 3) float16 (the centre's first) with each
    entry's smooth normal (its texel centre's) and the samples' weights (:func:`weights`),
    and the cosines of the directions asked last."""

    #: Entries per block of a cosine's evaluation (its temporaries: ~40 bytes a normal).
    BLOCK = 1 << 15

    def __init__(self, samples, N, correction, bump: str, weigh=None):
        if bump not in ("conty", "chiang"):
            raise ValueError(f"bump must be 'conty' or 'chiang', got {bump!r}")
        self.n16, self.N, self.bump = samples, np.asarray(N, np.float64), bump
        Q, K = samples.shape[:2]
        self.correction = (np.ones(Q, bool) if correction is None
                           else np.asarray(correction, bool))
        self.w = np.zeros((Q, K), np.float32)
        self.mean = np.zeros((Q, 3))
        self.reach_below = np.zeros(Q)
        alike = np.full(K, 1.0 / max(K - 1, 1), np.float32)     # wholly on the triangle
        alike[0] = 1.0 if K == 1 else 0.0
        for a in range(0, Q, self.BLOCK):
            e = slice(a, min(a + self.BLOCK, Q))
            n = self._unit(e)
            w = (np.broadcast_to(alike, (n.shape[0], K)) if weigh is None
                 else np.asarray(weigh(e), np.float32))
            self.w[e] = w
            m = np.einsum("qk,qkj->qj", w, n).astype(np.float64)
            m /= np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-12)
            self.mean[e] = m
            # how far the counted samples spread from their mean (over 90 degrees: any
            # direction may be faced)
            c = np.where(w > 0, np.einsum("qkj,qj->qk", n, m.astype(np.float32)), 1.0).min(1)
            self.reach_below[e] = np.where(c > 0, -np.sqrt(np.maximum(1.0 - c * c, 0.0)), -1.01)
        self.cache = {}
        self.keep = max(1, CACHE_BYTES // max(4 * Q, 1))
        # the terms that do not depend on the sun, made once where they fit (else per block)
        self.pre = None
        if Q * K * 21 <= PRECOMPUTE_BYTES:
            n = self._unit(slice(None))
            cos_sn = np.einsum("qkj,qj->qk", n, self.N.astype(np.float32))
            self.pre = (n, cos_sn, self._alpha2(cos_sn))

    @staticmethod
    def _alpha2(cos_sn) -> np.ndarray:
        cos_d = np.abs(cos_sn)
        return np.clip(0.125 * (1.0 / np.maximum(cos_d * cos_d, 1e-30) - 1.0), 0.0, 1.0)

    def _unit(self, e) -> np.ndarray:
        n = self.n16[e].astype(np.float32)
        return n / np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-12)

    def __len__(self) -> int:
        return len(self.n16)

    def _eval(self, e, L) -> np.ndarray:
        """(len(e),) float32: the mean cosine factor of entries ``e`` (indices or a slice)."""
        N = self.N[e]
        if self.pre is not None:
            n, cos_sn, alpha2 = (a[e] for a in self.pre)
        else:
            n = self._unit(e)
            cos_sn = np.einsum("qkj,qj->qk", n, N.astype(np.float32))           # (m, K)
            alpha2 = self._alpha2(cos_sn)
        cos_ni = n @ L.astype(np.float32)                                       # (m, K)
        cos_si = (N @ L).astype(np.float32)[:, None]                            # (m, 1)
        if self.bump == "chiang":        # bump_shadowing: Ng's sign cancels in the ratio
            den = cos_ni * cos_sn
            with np.errstate(divide="ignore", invalid="ignore"):
                g = np.where(den != 0, cos_si / den, 0.0)
            g2 = g * g
            term = np.where(g >= 1, 1.0, np.where(g < 0, 0.0, -g2 * g + g2 + g))
        else:                            # bump_correction (Conty Estevez et al.)
            cos_i = np.abs(cos_si)
            c2 = cos_i * cos_i
            tan2 = (1.0 - c2) / np.maximum(c2, 1e-30)
            g1 = 2.0 / (1.0 + np.sqrt(1.0 + alpha2 * tan2))
            g1 = np.where(cos_i >= 1, 1.0, np.where(cos_i < 1e-6, 0.0, g1))
            # 1 where the sample is the smooth normal or the material's bump map correction is
            # off (bump_correction's ``where(smoothing, g1, 1)``)
            g1 = np.where((np.abs(cos_sn) >= 1.0) | ~self.correction[e][:, None], 1.0, g1)
            term = np.where(cos_si * cos_sn * cos_ni < 0, 0.0, g1)
        return np.einsum("qk,qk->q", np.maximum(cos_ni, 0.0) * term,
                         self.w[e]).astype(np.float32)

    def cosines(self, L, entries=None) -> np.ndarray:
        """Each entry's mean cosine factor towards unit ``L`` (3,), float32: of every entry
        (Q,) (kept for the directions asked last), or of ``entries`` (indices) alone where
        they are a small part of the set and ``L`` was not asked yet (the horizons ask many
        directions of a few points at a time)."""
        L = np.asarray(L, np.float64)
        key = L.tobytes()
        got = self.cache.get(key)
        if got is not None:
            return got if entries is None else got[entries]
        Q = len(self.n16)
        if entries is not None and 4 * len(entries) < Q:
            return self._eval(np.asarray(entries, np.int64), L)
        out = np.empty(Q, np.float32)
        for a in range(0, Q, self.BLOCK):
            out[a:a + self.BLOCK] = self._eval(slice(a, a + self.BLOCK), L)
        if len(self.cache) >= self.keep:
            self.cache.pop(next(iter(self.cache)))
        self.cache[key] = out
        return out if entries is None else out[entries]


class NormalSet:
    """Sampled closure normals of some of a set of points: ``rows`` (M,) sorted point indices,
    theirs the entries ``pick`` (M,) of ``shared`` (:class:`_Shared`, shared by subsets and
    sub-samples)."""

    def __init__(self, rows, shared, pick):
        self.rows = np.asarray(rows, np.int64)
        self.shared, self.pick = shared, np.asarray(pick, np.int64)

    def __len__(self) -> int:
        return len(self.rows)

    def index(self, rows) -> np.ndarray:
        """Positions in :attr:`rows` of the points ``rows`` (N,), -1 where a point has none."""
        rows = np.asarray(rows, np.int64)
        if not len(self.rows):
            return np.full(len(rows), -1, np.int64)
        pos = np.minimum(np.searchsorted(self.rows, rows), len(self.rows) - 1)
        return np.where(self.rows[pos] == rows, pos, -1)

    def take(self, owners) -> "NormalSet | None":
        """The set of new points whose j-th takes point ``owners[j]``'s normals (a subset of
        the points, or sub-samples of their texels), or None where none has any."""
        pos = self.index(owners)
        have = np.nonzero(pos >= 0)[0]
        return NormalSet(have, self.shared, self.pick[pos[have]]) if len(have) else None

    def reach(self, sel, L) -> np.ndarray:
        """(m,) bool: whether one of the entries ``sel``'s counted samples may face unit
        ``L`` (3,): the mean within the samples' spread (conservative; no cosine made)."""
        e = self.pick[sel]
        sh = self.shared
        return sh.mean[e] @ np.asarray(L, np.float64) > sh.reach_below[e]

    def cosine(self, sel, L) -> np.ndarray:
        """The mean over each entry's sampled normals of the diffuse closure's cosine factor
        (:func:`.shading.cosine`'s, bump terminator term included, with the texel centre's
        smooth normal) (m,) float64 of the set's entries ``sel`` (a slice or indices) towards
        unit ``L`` (3,)."""
        return self.shared.cosines(L, self.pick[sel]).astype(np.float64)
