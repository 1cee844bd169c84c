"""The block viewport: clustered PCA over square texel blocks, relit in the node tree (bpy-free).

Mahajan et al. 2007 relight large images through a PCA per block of pixels: light transport is
locally low-dimensional, so a block needs far fewer components than the whole texture for the
same error, and a cast shadow that a global PCA smears over a large receiver stays sharp. This
module makes that model a GPU viewport: per pixel one block's components, no Python per light
change.

Shapes and units
----------------
* ``T``: the store, (S, P) float16, ``P = R * R`` texels row-major, row 0 at the bottom;
  values are ``E / pi`` of a white surface under a sun of unit normal irradiance
  (dimensionless).
* Blocks: ``B x B`` texels, ``nb = R // B`` per side; block ``b = by * nb + bx`` holds texel rows
  ``by B .. by B + B - 1`` and columns ``bx B ..``.
* Block ``b`` keeps at most ``K`` components: ``T[:, b] ~ V_b U_b`` with ``V_b`` (S, K)
  orthonormal columns (zero past the ``n_b`` its tolerance needs) and ``U_b = V_b^T T[:, b]``
  (uncentred: the best rank-``n_b`` fit in the Frobenius norm, no mean to carry).

The viewport's arrays (float32 here, half floats on disk and on the GPU)
-------------------------------------------------------------------------
* **cells**: every per-texel image in the *cell layout*, ``Rp = nb (B + 2)`` texels across:
  block ``b`` sits in its own ``(B + 2)^2`` cell whose one-texel ring holds the neighbouring
  texels (clamped at the texture's edge, :func:`cell_sources`). The eigen images ``E`` (K, Rp, Rp)
  hold ``V_b^T T`` of the cell's texels, ring included -- so a bilinear lookup inside a cell never
  mixes two blocks' bases, and the relight is continuous across block borders to the fit's
  error. The albedo is stored in the same layout.
* **tables** ``C`` (K, nb D, nb D): cell ``b``'s ``D x D`` texels hold
  ``c_{b,k}(w0) = sum_s kernel_s(w0, a) V_b[s, k]`` at the disk texel centres
  (:func:`.texture.disk_kernel_matrix`).

Per pixel at texture coordinate ``f = uv R`` (texels), per axis: ``b = clamp(floor(f / B), 0,
nb - 1)``; the eigen lookup at ``(f + 2 b + 1) / Rp``; the table lookup at ``(b D + 0.5 + g) /
(nb D)`` with ``g = clamp((x0 + 1) D / 2 - 0.5, 0, D - 1)`` for the light's disk point ``x0``
(bilinear, never leaving the cell). Radiance: ``albedo * sum_k C_k E_k``, with
``ceil(K / 3)`` table and ``ceil(K / 3)`` eigen RGB lookups plus the albedo.
:func:`viewport_relight` is the same in NumPy (the tests compare it with a Cycles render of the
node group, ``operators/preview/transport_preview.py``).

The fit
-------
One strip of blocks is read at a time (``(S, B + 2, R)`` float32: the bound on the fit's
memory besides the outputs). A block's basis is the exact SVD when ``K + oversample`` reaches the
block's smaller side, else a randomised range finder (Halko et al. 2011: ``K + oversample``
Gaussian probes, ``power`` power iterations) -- its residual is computed exactly either way
(``||X||^2 - ||V^T X||^2``), and :func:`fit` records how it was made.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .texture import disk_kernel_matrix
from ..io.npz import save_npz

FORMAT = "relightable_textures.block_viewport"
#: Bytes per texel of a half-float RGBA image on the GPU (Blender uploads float images as
#: RGBA16F).
HALF_RGBA = 8


@dataclass
class BlockViewport:
    """A fitted block viewport (see the module docstring for shapes and units)."""

    V: np.ndarray | None     # (nblocks, S, K) float16, orthonormal columns (zeros past dims);
                             # None until first needed when loaded from a file (``store``)
    eigen: np.ndarray        # (K, Rp, Rp) float32, cell layout
    dims: np.ndarray         # (nblocks,) components each block keeps
    resolution: int
    block: int
    residual: float          # relative Frobenius residual of T over all texels
    method: str              # "exact" or "randomised (K+o probes, q power iterations)"
    store: object = None     # the TransportStore the loadings are recovered from

    @property
    def k(self) -> int:
        return int(self.eigen.shape[0])

    def loadings(self) -> np.ndarray:
        """V, recovered from the store on first use after :func:`load`
        (:func:`recover_loadings`: one pass over T)."""
        if self.V is None:
            self.V = recover_loadings(self.store, self.eigen, self.block)
        return self.V

    @property
    def per_side(self) -> int:
        return self.resolution // self.block

    def relight_weights(self, indices, weights) -> np.ndarray:
        """The model's relight (R, R) of sparse light weights over the baked directions
        (no tables): ``sum_k (w . V_b[idx, k]) U_b[k]`` per block."""
        idx = np.asarray(indices)
        w = np.asarray(weights, np.float64)
        c = np.einsum("s,bsk->bk", w, self.loadings()[:, idx].astype(np.float64))   # (nb^2, K)
        return cells_relight(c.T.reshape(self.k, self.per_side, self.per_side), self.eigen,
                             self.block, self.resolution)

    def gpu_bytes(self, table_size: int) -> dict:
        """Bytes of the viewport's images on the GPU (half-float RGBA, the atlases' one-texel
        tile borders included)."""
        return gpu_bytes(self.resolution, self.block, self.k, table_size)

    def summary(self) -> dict:
        d = self.dims
        return {"kind": "blocks", "block": self.block, "blocks": int(len(d)),
                "components": self.k, "dims_min": int(d.min()), "dims_mean": float(d.mean()),
                "dims_max": int(d.max()), "residual": round(self.residual, 5),
                "method": self.method}


# ----------------------------------------------------------------------------------------------
# layout


def cell_sources(resolution: int, block: int) -> np.ndarray:
    """(Rp,) source texel of each cell-layout coordinate along one axis (ring texels: the
    neighbours, clamped at the texture's edge)."""
    R, B = int(resolution), int(block)
    if B < 1 or R % B:
        raise ValueError(f"block {B} must divide the resolution {R}")
    q = np.arange((R // B) * (B + 2))
    cell, local = np.divmod(q, B + 2)
    return np.clip(cell * B + local - 1, 0, R - 1)


def to_cells(image, block: int) -> np.ndarray:
    """A per-texel image (R, R, ...) in the cell layout (Rp, Rp, ...)."""
    img = np.asarray(image)
    src = cell_sources(img.shape[0], block)
    return img[src][:, src]


def cell_interior(cells, block: int) -> np.ndarray:
    """Inverse of :func:`to_cells` on the cells' interiors: (..., Rp, Rp) -> (..., R, R)."""
    a = np.asarray(cells)
    Rp = a.shape[-1]
    B = int(block)
    keep = (np.arange(Rp) % (B + 2) != 0) & (np.arange(Rp) % (B + 2) != B + 1)
    return a[..., keep, :][..., keep]


def cells_relight(coeffs, eigen, block: int, resolution: int) -> np.ndarray:
    """``sum_k coeffs[k, by, bx] E_k`` at the texel centres: (R, R) float32 from per-block
    coefficients (K, nb, nb) and cell-layout eigen images (K, Rp, Rp)."""
    E = cell_interior(eigen, block).astype(np.float64)                 # (K, R, R)
    c = np.repeat(np.repeat(np.asarray(coeffs, np.float64), block, 1), block, 2)
    return np.einsum("kyx,kyx->yx", c, E).astype(np.float32)


def gpu_bytes(resolution: int, block: int, k: int, table_size: int) -> dict:
    """GPU bytes of a block viewport of ``k`` components: the eigen atlas (``ceil(k/3)`` tiles
    plus the albedo tile, ``Rp`` across) and the table atlas (``ceil(k/3)`` tiles,
    ``nb * D`` across), half-float RGBA with the atlases' one-texel borders."""
    from ..io.atlas import atlas_layout

    nb = int(resolution) // int(block)
    tiles = -(-int(k) // 3)
    e = atlas_layout(tiles + 1, nb * (int(block) + 2))
    t = atlas_layout(tiles, nb * int(table_size))
    eb, tb = e["width"] * e["height"] * HALF_RGBA, t["width"] * t["height"] * HALF_RGBA
    return {"eigen_bytes": eb, "table_bytes": tb, "total_bytes": eb + tb,
            "side": max(e["width"], e["height"], t["width"], t["height"])}


def lookups_per_pixel(k: int) -> int:
    """Texture lookups per pixel of the block viewport's direct light."""
    return 2 * -(-int(k) // 3) + 1


def largest_k(resolution: int, block: int, table_size: int, budget_bytes: int,
              k_max: int = 48, max_side: int = 16384) -> int:
    """The most components (a multiple of three, at most ``k_max``) whose viewport fits
    ``budget_bytes`` and the GPU's ``max_side``; 0 when not even three do."""
    best = 0
    for k in range(3, int(k_max) + 1, 3):
        g = gpu_bytes(resolution, block, k, table_size)
        if g["total_bytes"] > budget_bytes or g["side"] > max_side:
            break
        best = k
    return best


# ----------------------------------------------------------------------------------------------
# the fit


def _basis(X: np.ndarray, k: int, tol: float, oversample: int, power: int, rng):
    """Orthonormal (S, n) basis of the block ``X`` (S, p) float64, n <= k: the fewest whose
    relative residual is at most ``tol`` (``tol = 0``: k, or the numerical rank). Returns
    (basis, ||X||^2, ||X||^2 - ||basis^T X||^2, exact)."""
    S, p = X.shape
    tot = float(np.einsum("ij,ij->", X, X))
    if tot <= 0.0:
        return np.zeros((S, 0)), 0.0, 0.0, True
    ell = min(k + oversample, S, p)
    exact = ell >= min(S, p)
    if exact:
        u, s, _ = np.linalg.svd(X, full_matrices=False)
    else:
        Y = X @ rng.standard_normal((p, ell))
        for _ in range(power):
            Y, _ = np.linalg.qr(Y)
            Y = X @ (X.T @ Y)
        Q, _ = np.linalg.qr(Y)
        ub, s, _ = np.linalg.svd(Q.T @ X, full_matrices=False)
        u = Q @ ub
    s2 = s.astype(np.float64) ** 2
    rank = int(np.count_nonzero(s > 1e-12 * s[0])) if s.size else 0
    n = min(k, rank)
    if tol > 0 and n > 0:
        left = tot - np.cumsum(s2[:n])
        ok = np.nonzero(left <= tol * tol * tot)[0]
        if ok.size:
            n = int(ok[0]) + 1
    return u[:, :n], tot, max(tot - float(s2[:n].sum()), 0.0), exact


def fit(store, block: int, k: int, tol: float = 0.0, oversample: int = 10, power: int = 1,
        seed: int = 0, progress=None) -> BlockViewport:
    """Fit the block viewport of a :class:`~.texture.TransportStore`.

    ``k``: components per block at most (the GPU budget sets it: :func:`largest_k`); ``tol``:
    relative Frobenius residual per block below which fewer are kept (0: always ``k``);
    ``progress(done, total)`` per strip. Float64 for the fit, float32 out."""
    R, B, K = int(store.resolution), int(block), int(k)
    if K < 1:
        raise ValueError(f"need at least one component per block, got {k}")
    src = cell_sources(R, B)
    nb = R // B
    arr = store.array
    S = arr.shape[0]
    Rp = nb * (B + 2)
    V = np.zeros((nb * nb, S, K), np.float16)   # (half: the tables it makes are half floats)
    E = np.zeros((K, Rp, Rp), np.float32)
    dims = np.zeros(nb * nb, np.int64)
    rng = np.random.default_rng(seed)
    tot2 = err2 = 0.0
    all_exact = True
    for by in range(nb):
        rows = src[by * (B + 2):(by + 1) * (B + 2)]
        lo, hi = int(rows.min()), int(rows.max()) + 1
        strip = np.asarray(arr[:, lo * R:hi * R], np.float32).reshape(S, hi - lo, R)[:, rows - lo]
        for bx in range(nb):
            cols = src[bx * (B + 2):(bx + 1) * (B + 2)]
            ext = strip[:, :, cols].reshape(S, -1).astype(np.float64)     # (S, (B+2)^2)
            inner = strip[:, 1:B + 1, bx * B:(bx + 1) * B].reshape(S, -1).astype(np.float64)
            basis, t2, e2, exact = _basis(inner, K, tol, oversample, power, rng)
            n = basis.shape[1]
            b = by * nb + bx
            V[b, :, :n] = basis
            dims[b] = n
            E[:n, by * (B + 2):(by + 1) * (B + 2), bx * (B + 2):(bx + 1) * (B + 2)] = \
                (basis.T @ ext).reshape(n, B + 2, B + 2)
            tot2 += t2
            err2 += e2
            all_exact &= exact
        if progress is not None:
            progress(by + 1, nb)
    method = "exact" if all_exact else f"randomised ({K}+{oversample} probes, {power} power)"
    return BlockViewport(V, E, dims, R, B, float(np.sqrt(err2 / tot2)) if tot2 > 0 else 0.0,
                         method)


# ----------------------------------------------------------------------------------------------
# tables and the twin of the node group


def tables(view: BlockViewport, dset, size: int, sun_angle_deg: float,
           kernel: str = "linear", chunk: int = 256) -> np.ndarray:
    """(K, nb D, nb D) float32: cell ``b`` holds ``c_{b,k}`` on the ``D x D`` disk grid
    (``chunk`` blocks at a time, so no (S, blocks K) copy of the loadings is made)."""
    W = disk_kernel_matrix(dset, size, sun_angle_deg, kernel)               # (D*D, S)
    nb, K, D = view.per_side, view.k, int(size)
    out = np.empty((nb * nb, K, D * D), np.float32)
    V = view.loadings()
    for a in range(0, nb * nb, chunk):
        Vc = V[a:a + chunk].astype(np.float64)                              # (c, S, K)
        c = Vc.shape[0]
        prod = W @ Vc.transpose(1, 0, 2).reshape(Vc.shape[1], c * K)         # (D*D, c*K)
        out[a:a + c] = np.asarray(prod).reshape(D * D, c, K).transpose(1, 2, 0)
    out = out.reshape(nb, nb, K, D, D).transpose(2, 0, 3, 1, 4)            # (K, nb, D, nb, D)
    return np.ascontiguousarray(out).reshape(K, nb * D, nb * D)


def table_coefficients(table, direction, size: int) -> np.ndarray:
    """Per-block coefficients (K, nb, nb) at a light direction: each cell's bilinear lookup,
    as the GPU's Linear sampler reads it at ``(b D + 0.5 + g) / (nb D)``; zero below the
    horizon."""
    from ..sphere.hemisphere import hemisphere_to_disk, normalize_directions

    t = np.asarray(table, np.float64)
    K, D = t.shape[0], int(size)
    nb = t.shape[1] // D
    d = normalize_directions(np.asarray(direction, np.float64).reshape(1, 3))[0]
    if d[2] <= 0:
        return np.zeros((K, nb, nb))
    cells = t.reshape(K, nb, D, nb, D)
    xy = hemisphere_to_disk(d[None])[0]
    g = [float(np.clip((c + 1.0) * 0.5 * D - 0.5, 0.0, D - 1.0)) for c in xy]
    x0, y0 = (min(int(np.floor(v)), D - 2) for v in g)
    ax, ay = g[0] - x0, g[1] - y0
    return ((1 - ax) * (1 - ay) * cells[:, :, y0, :, x0] + ax * (1 - ay) * cells[:, :, y0, :, x0 + 1]
            + (1 - ax) * ay * cells[:, :, y0 + 1, :, x0] + ax * ay * cells[:, :, y0 + 1, :, x0 + 1])


def viewport_relight(eigen, table, albedo_cells, direction, block: int, resolution: int,
                     size: int) -> np.ndarray:
    """NumPy twin of the block group at the texel centres (direct light, intensity 1):
    (R, R, 3) from the cell-layout eigen images (K, Rp, Rp), the tables (K, nb D, nb D) and
    the cell-layout albedo (Rp, Rp, 3)."""
    c = table_coefficients(table, direction, size)
    e = cells_relight(c, eigen, block, resolution).astype(np.float64)
    a = cell_interior(np.moveaxis(np.asarray(albedo_cells, np.float64), -1, 0), block)
    return (e[None] * a).transpose(1, 2, 0).astype(np.float32)


# ----------------------------------------------------------------------------------------------
# choosing the block size and the components within a GPU budget

#: Block sides tried (texels), and the most components per block (17 lookups per pixel: fewer
#: than the T viewport's 21 for a point sun).
BLOCKS = (8, 16, 32, 64)
K_MAX = 24
#: Sampled regions (side: the largest block tried) on which the candidates are compared.
REGIONS = 6


def candidates(resolution: int, table_size: int, budget_bytes: int, k_max: int = K_MAX,
               blocks=BLOCKS, max_side: int = 16384) -> list:
    """[(block, k)] that fit the budget: for each block side dividing the resolution (at least
    two blocks across), the most components up to ``k_max``. The error falls with ``k`` at a
    given block, so only the largest that fits is worth comparing."""
    out = []
    for B in blocks:
        if resolution % B or resolution // B < 2:
            continue
        k = largest_k(resolution, B, table_size, budget_bytes, k_max, max_side)
        if k:
            out.append((B, k))
    return out


def choose(store, table_size: int, budget_bytes: int, k_max: int = K_MAX, blocks=BLOCKS,
           regions: int = REGIONS, seed: int = 0) -> dict:
    """The block side and components of the block viewport: each candidate of
    :func:`candidates` is fitted on the same ``regions`` sampled square regions of T (side: the
    largest candidate block; a random draw among the regions with light, so empty UV space is
    not what is compared) and the lowest relative residual wins (ties: the fewer bytes).

    Returns ``{"block", "k", "residual_sampled", "tried": [{block, k, residual, mib}]}``,
    ``{}`` when nothing fits the budget."""
    R = int(store.resolution)
    cands = candidates(R, table_size, budget_bytes, k_max, blocks)
    if not cands:
        return {}
    side = max(B for B, _ in cands)
    arr = store.array
    S = arr.shape[0]
    n = R // side
    rng = np.random.default_rng(seed)
    cells = rng.permutation(n * n)[:max(4 * regions, regions)]
    energy = []
    for c in cells:   # a cheap figure: every 4th direction on the region's middle texel row
        cy, cx = divmod(int(c), n)
        start = (cy * side + side // 2) * R + cx * side
        energy.append(float(np.square(np.asarray(arr[::4, start:start + side],
                                                 np.float64)).sum()))
    lit = [int(c) for c, e in zip(cells, energy) if e > 0] or [int(c) for c in cells]
    picked = lit[:regions]     # (cells is a random permutation: a random draw of lit regions)
    data = []
    for c in picked:
        cy, cx = divmod(c, n)
        strip = np.asarray(arr[:, cy * side * R:(cy + 1) * side * R], np.float32)
        data.append(strip.reshape(S, side, R)[:, :, cx * side:(cx + 1) * side])
    tried = []
    for B, k in cands:
        tot = err = 0.0
        for X in data:
            for y in range(0, side, B):
                for x in range(0, side, B):
                    blk = X[:, y:y + B, x:x + B].reshape(S, -1).astype(np.float64)
                    _, t2, e2, _ = _basis(blk, k, 0.0, 10, 1, rng)
                    tot += t2
                    err += e2
        tried.append({"block": B, "k": k, "residual": round(float(np.sqrt(err / tot))
                                                            if tot > 0 else 0.0, 5),
                      "mib": round(gpu_bytes(R, B, k, table_size)["total_bytes"] / 2**20, 1)})
    best = min(tried, key=lambda t: (t["residual"], t["mib"]))
    return {"block": best["block"], "k": best["k"], "residual_sampled": best["residual"],
            "tried": tried}


# ----------------------------------------------------------------------------------------------
# the file


def save(path: str, view: BlockViewport) -> None:
    """Write the viewport atomically (NPZ): the cell-layout eigen images in half floats and the
    per-block figures. The loadings are not stored: they are T's projection on the eigen
    images (:func:`recover_loadings`), and T is kept with every bake; stored, they would take
    nearly T's own size at small blocks (512^2, 8^2 blocks x 24: 629 MB against T's 839)."""
    from ..io import atomic, versions

    with atomic.atomic_path(path) as tmp:
        save_npz(tmp, eigen=view.eigen.astype(np.float16), dims=view.dims,
                 resolution=np.array(view.resolution), block=np.array(view.block),
                 residual=np.array(view.residual), method=np.array(view.method),
                 components=np.array(view.k), directions=np.array(view.loadings().shape[1]),
                 **{k: np.array(v) for k, v in versions.stamp(FORMAT).items()})


def recover_loadings(store, eigen, block: int) -> np.ndarray:
    """The loadings (nblocks, S, K) float16 of a block viewport from T and its eigen images:
    ``U_b = V_b^T X_b`` has orthogonal rows of squared norms ``s^2`` (the block's singular
    values), so ``V_b = X_b U_b^T diag(1 / s^2)`` -- one strip of T at a time. Components
    with ``s = 0`` (past a block's rank) stay zero. The eigen images' half floats bound the
    error (about 1e-3 relative)."""
    R, B = int(store.resolution), int(block)
    nb = R // B
    arr = store.array
    S = arr.shape[0]
    E = cell_interior(np.asarray(eigen, np.float32), B)                    # (K, R, R)
    K = E.shape[0]
    V = np.zeros((nb * nb, S, K), np.float16)
    for by in range(nb):
        strip = np.asarray(arr[:, by * B * R:(by + 1) * B * R], np.float32).reshape(S, B, R)
        for bx in range(nb):
            X = strip[:, :, bx * B:(bx + 1) * B].reshape(S, -1).astype(np.float64)
            U = E[:, by * B:(by + 1) * B, bx * B:(bx + 1) * B].reshape(K, -1).astype(np.float64)
            s2 = np.einsum("kp,kp->k", U, U)
            keep = s2 > 1e-20 * max(float(s2.max()), 1e-300)
            if keep.any():
                V[by * nb + bx][:, keep] = (X @ U[keep].T) / s2[keep]
    return V


def load(path: str, store) -> BlockViewport:
    """The viewport :func:`save` wrote; its loadings are recovered from ``store`` (T) when
    first needed (re-tabulating for a new sun size, a relight of the model). Read as a file
    from elsewhere (:func:`..io.untrusted.open_npz`): its resolution and direction count must
    be T's, its block divide the resolution, ``eigen`` be (K, Rp, Rp) with K <= S and
    ``Rp = nb (B + 2)``, ``dims`` (nb^2,) counts in 0..K -- all from the headers before any
    array is inflated; the eigen images finite."""
    from ..io import untrusted as ut, versions

    with ut.open_npz(path, stored=True) as z:
        versions.check({"format": ut.npz_scalar(z, "format", str),
                        "format_version": ut.npz_scalar(z, "format_version", int)},
                       FORMAT, path, "a block viewport")
        block, R = ut.npz_scalar(z, "block", int), ut.npz_scalar(z, "resolution", int)
        S = ut.npz_scalar(z, "directions", int)
        if R != store.resolution or S != store.directions.size:
            raise ut.UntrustedFileError(path, f"was fitted to another T ({R}^2, {S} "
                                              f"directions; this T: {store.resolution}^2, "
                                              f"{store.directions.size})")
        ut.check_count(path, block, R, "block", lo=1)
        if R % block:
            raise ut.UntrustedFileError(path, f"block {block} does not divide {R}")
        nb = R // block
        Rp = nb * (block + 2)
        eigen = z.get("eigen", shape=(None, Rp, Rp), dtype="f")
        if eigen.shape[0] > S:
            raise ut.UntrustedFileError(path, f"has {eigen.shape[0]} components for {S} "
                                              "directions")
        ut.check_values(path, eigen, what="eigen-image values")
        dims = z.get("dims", shape=(nb * nb,), dtype="iu")
        if dims.size and (dims.min() < 0 or dims.max() > eigen.shape[0]):
            raise ut.UntrustedFileError(path, f"has block dims outside 0..{eigen.shape[0]}")
        return BlockViewport(None, np.asarray(eigen, np.float32), dims, R, block,
                             ut.npz_scalar(z, "residual", float),
                             ut.npz_scalar(z, "method", str), store)
