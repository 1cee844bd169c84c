"""Denoise the bounce terms over the surface and compose the second bounce from the first (bpy-free).

Two measured facts about the per-vertex transfer tensors (:mod:`.ptt`) of the demo room
(4,454 vertices, bounce terms at 32 samples, ``benchmarks/bench_materials.py``):

* **The bounce terms are noise-bound.** At a baked direction the one-bounce term ``O`` was
  0.030-0.039 (of the norm of E) off a 256-sample Cycles bake of the same light, where two such
  truths differ by 0.010. The noise is the same at every direction (one seed: every direction
  sees the same hemisphere samples per vertex), so a low rank over the directions does not
  remove it (measured: rank 16 of 64 left it at 0.034-0.044); over the surface it does.
  :func:`smoothing_operator` is a normalised Gaussian over the receivers within ``radius`` whose
  normals agree (a wall's corner with the floor is not blurred across): at twice the median
  receiver spacing it took ``O``'s error at baked directions to 0.014-0.022.
* **The two-bounce term is too coarse in the light's direction.** It is baked at few
  directions (the paper's 6x2x2 cube map; here ``hemi:8``), so at a low sun it borrows from
  higher neighbours: 6x too much two-bounce light at a 10-degree sun. The two-bounce light is the
  one-bounce light reflected once more, and the one-bounce term is finely sampled; so
  :class:`BounceTransfer` composes it: the one-bounce irradiance on region ``r2``'s receivers,
  times their albedo, summed over patches of ``r2``, times each patch's transfer to every
  receiver (Hasan et al. 2006's direct-to-indirect transfer at patch resolution). The transfer
  ``T`` (K, V) is fitted (ridge least squares) from the bake itself: at every one-bounce
  direction, the exact direct light on each patch against the baked one-bounce term, and at
  every two-bounce direction the one-bounce light on each patch against the baked two-bounce
  term (:func:`fit_transfer`). Fitted to direct light alone it composed 10-60 % low
  (reflected light gathers in corners, direct light lies evenly); a scale per region pair,
  fitted against the baked two-bounce term at its directions, calibrates what is left.
  Measured at 7 held-out suns: the relative error of E went from 0.066 / 0.089 (file colours
  / both walls white) to 0.047 / 0.057 with both (direct light alone in the fit).

Shapes: V receivers, R+1 regions (0 fixed), K patches in all; units as in :mod:`.ptt`
(irradiance per unit normal irradiance of the light).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Smoothing radius in median receiver spacings (0: no smoothing), see the module docstring.
SMOOTH_SPACINGS = 2.0
#: ... but never wider than this fraction of the receivers' bounding-box diagonal: indirect light
#: varies on the scale of the scene, and on a coarse mesh two spacings are much of it (the test
#: room, 350 vertices: 17 % of the room; its error at a baked direction rose from 0.032 to 0.049).
SMOOTH_MAX_FRACTION = 0.03
#: Neighbours whose normals differ by more than this cosine are not averaged.
SMOOTH_MIN_COS = 0.95
#: Patches per region for the composition (measured: 16, 32 and 48 within 0.001 of each other).
PATCHES = 32
#: The composition needs at least this many one-bounce directions, and twice the two-bounce
#: ones (with as many, the blended two-bounce term is as fine in direction as the first);
#: a region gets at most half the one-bounce directions as patches (a determined fit).
MIN_ONE_DIRECTIONS = 16
#: A region whose fit explains less of its baked one-bounce energy than this is not composed
#: into (its pairs keep the baked two-bounce term); see :func:`fit_transfer`.
MIN_EXPLAINED = 0.9
#: Calibration scales outside this range leave the pair baked (see :func:`calibrate`). Measured:
#: 0.96-1.7 on the demo room at 32 patches per region, 0.28-2.7 at 8 (demo and test rooms); at
#: the test room's 0.28 the composition still beat the blended term at a 10-degree sun (0.021
#: against 0.147), so the range only catches a calibration that has gone wild.
SCALE_RANGE = (0.2, 5.0)
#: Ridge weight of the transfer fit, relative to the mean diagonal of the normal matrix.
RIDGE = 1e-2
#: Weight of the two-bounce observations in the transfer fit, relative to equal total weight
#: with the one-bounce ones (measured best 0.2-0.3 at 16 and 64 samples, :func:`fit_transfer`).
TWO_WEIGHT = 0.3


def smoothing_operator(positions: np.ndarray, normals: np.ndarray, spacings: float = SMOOTH_SPACINGS,
                       min_cos: float = SMOOTH_MIN_COS):
    """Row-normalised sparse (V, V) Gaussian weights over the receivers.

    positions (V, 3) metres, normals (V, 3) unit. Receivers closer than ``spacings`` times the
    median distance to the nearest other receiver (at most :data:`SMOOTH_MAX_FRACTION` of the
    bounding-box diagonal), with normals within ``min_cos``, are averaged with weight
    ``exp(-d^2 / (2 sigma^2))``, ``sigma`` half the radius. Returns
    ``(operator, radius_m)``; None as operator when ``spacings`` is 0 or there is nothing to
    average."""
    from scipy import sparse
    from scipy.spatial import cKDTree

    V = len(positions)
    # a vertex without faces (no normal, placed at the origin) is left alone
    valid = np.linalg.norm(np.asarray(normals, np.float64), axis=1) > 0.5
    idx = np.nonzero(valid)[0]
    pos = np.asarray(positions, np.float64)[idx]
    nrm = np.asarray(normals, np.float64)[idx]
    if spacings <= 0 or len(idx) < 2:
        return None, 0.0
    tree = cKDTree(pos)
    # the nearest other position: face corners of one vertex share its position (per-corner
    # bakes), so look a few neighbours on and skip the zero distances
    dist = tree.query(pos, k=min(len(pos), 16))[0][:, 1:]
    dist = np.where(dist > 0, dist, np.inf).min(axis=1)
    nn = dist[np.isfinite(dist)]
    if not len(nn):
        return None, 0.0
    diagonal = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0)))
    radius = float(min(spacings * np.median(nn), SMOOTH_MAX_FRACTION * diagonal))
    pairs = tree.query_pairs(radius, output_type="ndarray")
    if not len(pairs):
        return None, radius
    i, j = pairs[:, 0], pairs[:, 1]
    keep = np.einsum("ij,ij->i", nrm[i], nrm[j]) > min_cos
    i, j = i[keep], j[keep]
    d = np.linalg.norm(pos[i] - pos[j], axis=1)
    w = np.exp(-0.5 * (d / (radius / 2.0)) ** 2)
    i, j = idx[i], idx[j]
    rows = np.concatenate([i, j, np.arange(V)])
    cols = np.concatenate([j, i, np.arange(V)])
    W = sparse.csr_matrix((np.concatenate([w, w, np.ones(V)]), (rows, cols)), shape=(V, V))
    op = (sparse.diags(1.0 / np.asarray(W.sum(axis=1)).ravel()) @ W).astype(np.float32)
    return op.tocsr(), radius


def composes(one_directions: int, two_directions: int) -> int:
    """Patches per region for the composition, or 0 where it is not done (see
    :data:`MIN_ONE_DIRECTIONS`)."""
    if two_directions < 1 or one_directions < max(MIN_ONE_DIRECTIONS, 2 * two_directions):
        return 0
    return min(PATCHES, one_directions // 2)


def smooth(op, term: np.ndarray, block: int = 64) -> np.ndarray:
    """``term`` (..., V) float32 with ``op`` applied over its last axis, ``block`` rows at a
    time (float32: a block's copy, not the term's, is the extra memory)."""
    if op is None or not term.size:
        return term
    flat = term.reshape(-1, term.shape[-1])
    out = np.empty(flat.shape, np.float32)
    for a in range(0, len(flat), block):
        out[a:a + block] = (op @ np.asarray(flat[a:a + block], np.float32).T).T
    return out.reshape(term.shape)


def region_patches(positions: np.ndarray, normals: np.ndarray, region: np.ndarray,
                   regions: int, per_region: int = PATCHES, seed: int = 0):
    """Cluster each region's receivers into at most ``per_region`` patches (k-means on position
    and twice the normal: a patch does not wrap round a corner). Returns ``patch`` (V,) int32
    (the patch of each receiver; a faceless vertex stays in patch 0, where its zero light adds
    nothing) and ``patch_region`` (K,) int16."""
    from scipy.cluster.vq import kmeans2

    patch = np.zeros(len(region), np.int32)
    owner, k0 = [], 0
    feat = np.concatenate([np.asarray(positions, np.float64),
                           2.0 * np.asarray(normals, np.float64)], axis=1)
    valid = np.linalg.norm(np.asarray(normals, np.float64), axis=1) > 0.5
    for r in range(regions):
        idx = np.nonzero((region == r) & valid)[0]
        if not len(idx):
            continue
        k = min(per_region, len(idx))
        if k == len(idx):
            lab = np.arange(k)
        else:
            _, lab = kmeans2(feat[idx], k, minit="++", seed=np.random.default_rng(seed + r))
        used, lab = np.unique(lab, return_inverse=True)
        patch[idx] = k0 + lab
        owner += [r] * len(used)
        k0 += len(used)
    return patch, np.asarray(owner, np.int16)


def _patch_sums(values: np.ndarray, patch: np.ndarray, K: int) -> np.ndarray:
    """(..., V) -> (..., K): each patch's sum of ``values`` over its receivers."""
    flat = values.reshape(-1, values.shape[-1])
    out = np.stack([np.bincount(patch, weights=row, minlength=K) for row in flat])
    return out.reshape(*values.shape[:-1], K)


@dataclass
class BounceTransfer:
    """Second-bounce composition: ``patch`` (V,) int32, ``patch_region`` (K,) int16,
    ``transfer`` (K, V) float32 (irradiance at each receiver per unit of albedo x irradiance
    summed over a patch's receivers), ``source_albedo`` (V, 3) float32 (a fixed receiver's
    colour; 1 on editable ones, whose colour is the run-time coefficient), ``scale`` (R+1, R+1)
    float64 (calibration per pair ``r1 -> r2``; 0 where region ``r2`` has no receivers: that
    pair keeps the baked two-bounce term)."""

    patch: np.ndarray
    patch_region: np.ndarray
    transfer: np.ndarray
    source_albedo: np.ndarray
    scale: np.ndarray

    def compose(self, one: np.ndarray) -> np.ndarray:
        """The two-bounce irradiance (3, R+1, R+1, V) float32 from the one-bounce irradiance
        ``one`` (3, R+1, V) of the same light: ``[c, r1, r2, v]`` is the light from region
        ``r1`` reflected once more off ``r2`` (before the region coefficients)."""
        return self.compose_sources(one, self.scale)

    def compose_sources(self, one: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """:meth:`compose` for any N sources of one-bounce light: ``one`` (3, N, V) -> (3, N,
        R+1, V), each source's light reflected once more off each region ``r2``, times
        ``scale`` (N, R+1) (0: not composed)."""
        return self.spread(self.patch_light(one), scale)

    def patch_light(self, one: np.ndarray) -> np.ndarray:
        """``one`` (3, N, V) irradiance -> (3, N, K) float32: each patch's sum over its
        receivers of albedo x irradiance, the light it reflects (before a region's edited
        colour), what :meth:`spread` and :meth:`contract` take."""
        C, N, V = one.shape
        src = (one * self.source_albedo.T[:, None, :]).reshape(C * N, V)
        if getattr(self, "_members", None) is None:   # (K, V): 1 where a receiver is a patch's
            from scipy import sparse

            self._members = sparse.csr_matrix(
                (np.ones(V, np.float32), (self.patch, np.arange(V))),
                shape=(len(self.patch_region), V))
        # a sparse product, not _patch_sums' bincount per row: 0.1 against 0.6 ms at 13K
        return np.asarray(self._members @ src.T, np.float32).T.reshape(C, N, -1)

    def spread(self, Q: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """The patches' light ``Q`` (3, N, K) over the receivers, region by region: (3, N,
        R+1, V) float32, times ``scale`` (N, R+1)."""
        C, N, K = Q.shape
        R1, V = self.scale.shape[1], self.transfer.shape[1]
        out = np.zeros((C, N, R1, V), np.float32)
        Q = Q.reshape(C * N, K)
        for r2 in range(R1):
            ks = np.nonzero(self.patch_region == r2)[0]
            if not len(ks) or not np.any(scale[:, r2]):
                continue
            if ks[-1] - ks[0] + 1 == len(ks):   # a region's patches are contiguous: no copy
                ks = slice(int(ks[0]), int(ks[-1]) + 1)
            block = (Q[:, ks] @ self.transfer[ks]).reshape(C, N, V)
            out[:, :, r2] = block * np.asarray(scale, np.float32)[None, :, r2, None]
        return out

    def contract(self, Q: np.ndarray, coefficients: np.ndarray,
                 scale: np.ndarray) -> np.ndarray:
        """``sum_{n, r2} coefficients[n, r2] * spread(Q, scale)[:, n, r2]`` (3, V) float32
        without spreading each source over the receivers: the coefficients (N, R+1, 3) (the
        edited colours of a pair) weigh the patches first, then a (K,) x (K, V) product per
        channel (at 13K vertices 0.2 ms in all, where spreading the 9 pairs took 2.8 ms and
        one (3, K) x (K, V) product 0.7 ms: OpenBLAS's sgemm is slow for 3 rows)."""
        owner = self.patch_region.astype(np.intp)
        w = (np.asarray(coefficients, np.float32)[:, owner]
             * np.asarray(scale, np.float32)[:, owner, None])                   # (N, K, 3)
        A = np.einsum("nkc,cnk->ck", w, Q)                                      # (3, K)
        out = np.empty((len(A), self.transfer.shape[1]), np.float32)
        for c in range(len(A)):
            out[c] = A[c] @ self.transfer
        return out

    def source_scale(self, sources: np.ndarray) -> np.ndarray:
        """Calibration (N, R+1) for light sources that are not baked two-bounce pairs (a glossy
        anchor of region ``sources[i]``): the pair's own scale, or where that pair was left
        blended (a flat wall does not light itself diffusely, a glossy one may) the median of
        ``r2``'s composed pairs; 0 where ``r2`` is not composed into at all."""
        out = self.scale[np.asarray(sources, np.int64)].copy()
        for r2 in range(self.scale.shape[1]):
            col = self.scale[:, r2]
            if np.any(col):
                out[out[:, r2] == 0, r2] = float(np.median(col[col > 0]))
        return out

    def covers(self) -> np.ndarray:
        """(R+1, R+1) bool: the pairs :meth:`compose` gives (the rest stay baked)."""
        return self.scale != 0

    @property
    def nbytes(self) -> int:
        return int(self.transfer.nbytes + self.patch.nbytes + self.source_albedo.nbytes)


def fit_transfer(one: np.ndarray, direct_one: np.ndarray, patch: np.ndarray,
                 patch_region: np.ndarray, source_albedo: np.ndarray, ridge: float = RIDGE,
                 two: np.ndarray | None = None, one_at: np.ndarray | None = None,
                 two_weight: float | None = None):
    """Fit ``T`` (K, V) float32: the irradiance each patch's reflected light gives every
    receiver.

    Observations, per region r (its patches ``k``):

    * the one-bounce term ``one`` (S1, 3, R+1, V) against the exact direct term at its
      directions ``direct_one`` (S1, V) (visibility x cosine): ``one[s, c, r] ~ P[s, c] @ T_r``
      with ``P`` each patch's sum of albedo x direct light;
    * with ``two`` (S2, 3, R+1, R+1, V), the baked two-bounce term, and ``one_at`` (S2, 3,
      R+1, V), the one-bounce light at its directions: ``two[s, c, r1, r] ~ Q[s, c, r1] @ T_r``
      with ``Q`` each patch's sum of albedo x the light off ``r1``, weighted by
      ``two_weight`` (default :data:`TWO_WEIGHT`) relative to both blocks weighing the same in
      total. Direct light lies evenly over a lit patch; reflected light does not (it gathers
      in the corners), and a ``T`` fitted to direct light alone composed the second bounce up
      to 57 % low (demo room: calibration scales 1.01-1.57, 64 samples). Measured on the
      demo room at the 7 held-out suns of ``benchmarks/bench_materials.py`` (two-bounce
      part's error, of the norm of E, file colours / both walls white): at 16 samples 0.018 /
      0.025 with direct light alone, 0.016 / 0.023 at weight 0.3, 0.018 / 0.026 at 1 (the
      noisy two-bounce bake pulls too hard); at 64 samples 0.018 / 0.024, 0.015 / 0.021 at
      0.3 (0.1-1: 0.015-0.017). Scales then 1.01-1.20.

    Ridge least squares in float64 with ``ridge`` x the mean diagonal added: that bounds the
    condition number of what is solved by ``1 + K_r / ridge`` (3,201 at 32 patches), so the
    solve is stable by construction and its condition says nothing about the fit. Returns
    ``(T, explained, explained_two)``: per region the fraction of the baked one-bounce (and
    two-bounce: empty without ``two``) energy the fit explains (``1 - |B - A T|^2 / |B|^2``),
    which says whether the patch model holds -- it does not when the region's reflected light
    does not follow its patches' light (light from meshes that are not receivers, patches
    never lit directly)."""
    S1, C, R1, V = one.shape
    K = len(patch_region)
    P = _patch_sums(source_albedo.T[None, :, :] * np.asarray(direct_one, np.float64)[:, None, :],
                    patch, K)                                                   # (S1, 3, K)
    Q = None
    if two is not None and one_at is not None and len(two):
        Q = _patch_sums(source_albedo.T[None, :, None, :] * np.asarray(one_at, np.float64),
                        patch, K)                                               # (S2, 3, R1, K)
    T = np.zeros((K, V), np.float32)
    explained, explained_two = {}, {}
    for r in range(R1):
        ks = np.nonzero(patch_region == r)[0]
        if not len(ks):
            continue
        A = P[:, :, ks].reshape(S1 * C, len(ks))
        B = one[:, :, r, :].reshape(S1 * C, V).astype(np.float64)
        A_all, B_all = A, B
        if Q is not None:
            A2 = Q[:, :, :, ks].reshape(-1, len(ks))
            B2 = two[:, :, :, r, :].reshape(-1, V).astype(np.float64)
            if np.any(A2):   # equal total weight: rms(A) sqrt(rows) alike
                k = (np.sqrt(np.mean(A * A) * len(A) / (np.mean(A2 * A2) * len(A2)))
                     if np.any(A) else 1.0) * (TWO_WEIGHT if two_weight is None else two_weight)
                A_all, B_all = np.concatenate([A, k * A2]), np.concatenate([B, k * B2])
        G = A_all.T @ A_all
        lam = ridge * max(float(np.trace(G)) / len(ks), 1e-30)
        G += lam * np.eye(len(ks))
        Tr = np.linalg.solve(G, A_all.T @ B_all)
        T[ks] = Tr
        energy = float(np.sum(B * B))
        explained[r] = 1.0 - float(np.sum((B - A @ Tr) ** 2)) / energy if energy > 0 else 0.0
        if A_all is not A:
            e2 = float(np.sum(B2 * B2))
            explained_two[r] = 1.0 - float(np.sum((B2 - A2 @ Tr) ** 2)) / e2 if e2 > 0 else 0.0
    return T, explained, explained_two


def calibrate(transfer: BounceTransfer, one_at: list, two: np.ndarray) -> np.ndarray:
    """Scale (R+1, R+1) per pair ``r1 -> r2`` that best fits the composition of ``one_at[s]``
    (3, R+1, V), the one-bounce irradiance at the two-bounce directions, to the baked
    two-bounce term ``two`` (S2, 3, R+1, R+1, V) (least squares; 0 where nothing composes, or
    where the scale falls outside :data:`SCALE_RANGE`: the composition is then not the shape of
    the baked light, only rescaled, and the pair keeps the baked term)."""
    R1 = two.shape[2]
    num, den = np.zeros((R1, R1)), np.zeros((R1, R1))
    probe = BounceTransfer(transfer.patch, transfer.patch_region, transfer.transfer,
                           transfer.source_albedo, np.ones((R1, R1)))
    for s, one in enumerate(one_at):
        c = probe.compose(np.asarray(one, np.float32)).astype(np.float64)
        b = two[s].astype(np.float64)
        num += np.einsum("cabv,cabv->ab", c, b)
        den += np.einsum("cabv,cabv->ab", c, c)
    scale = np.where(den > 0, num / np.maximum(den, 1e-300), 0.0)
    return np.where((scale >= SCALE_RANGE[0]) & (scale <= SCALE_RANGE[1]), scale, 0.0)
