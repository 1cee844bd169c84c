"""The texture bake's indirect light gathered by rays over T's own directions (bpy-free).

The transport bake relights a sun's direct light from ``T`` (one row per baked direction) and
its indirect light from a low-order steerable bake (:mod:`.texture`, Cycles). Here the indirect
light comes from ``T`` itself, as the material edits gather theirs (:mod:`.gathered_transfer`):
every gather point -- a texel centre of the indirect grid (``RI x RI``) -- casts ``K``
cosine-weighted rays once; a ray that meets a receiver's front side at UV ``uv`` reads that
receiver's direct light there, so for *every* baked direction ``s`` at once::

    I1[s, p] = 1/K  sum_k  albedo(q_k) * T[s, q_k]          (q_k: the hit's texel at T's side)
    I2[s, p] = 1/K  sum_k  albedo(q_k) * I1[s, g(q_k)]      (g: the hit's gather point)

``I = I1 + I2 + ...`` is ``E_indirect / pi`` of a white surface per unit normal irradiance of
the sun from ``s``, in the units of ``T`` (cos x V / pi); the radiance the bake adds at a texel is
``albedo(p) * I``. The rays do not depend on the light, so their cost is paid once; each bounce
is one sparse product over all directions.

Rays that meet a non-receiver, a receiver's back side, or nothing add nothing (counted in
:class:`Gather`); a hit whose gather point is not covered by the indirect grid adds nothing to
the second bounce.

Shapes: ``H`` front hits on receivers; receivers stacked -- T's texels as columns
``offset_r + texel`` (``n_t`` in all), gather points as ``offset_r + point`` (``P`` in all).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry.barycentric import barycentric
from .gathered_transfer import cosine_directions


def uv_texel(uv, resolution: int) -> np.ndarray:
    """Flat texel index ``row * R + col`` (row 0 at v = 0) of the texel holding each UV
    (M, 2) on an ``R x R`` grid, clamped to the grid."""
    uv = np.asarray(uv, np.float64)
    R = int(resolution)
    col = np.clip(np.floor(uv[:, 0] * R), 0, R - 1).astype(np.int64)
    row = np.clip(np.floor(uv[:, 1] * R), 0, R - 1).astype(np.int64)
    return row * R + col


def hit_barycentrics(vertices, triangles, hit, origins, directions, distance) -> np.ndarray:
    """Barycentric weights (M, 3) of the hit points ``origins + distance * directions`` on
    triangles ``hit`` (M,) of the mesh (vertices (N, 3), triangles (T, 3)), float64
    (:func:`..geometry.barycentric.barycentric`: projected, clipped to the triangle)."""
    V = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)[np.asarray(hit, np.int64)]
    X = (np.asarray(origins, np.float64)
         + np.asarray(directions, np.float64) * np.asarray(distance, np.float64)[:, None])
    return barycentric(X, V[t[:, 0]], V[t[:, 1]], V[t[:, 2]])


@dataclass
class Gather:
    """The front hits of every gather point's rays on the receivers.

    Attributes
    ----------
    rays : int  (K, per gather point);  points : int  (P);  point : (H,) int64 the gather
    point of each hit;  texel : (H,) int64 its stacked texel at T's side;  target : (H,) int64
    its stacked gather point (-1: not covered by the indirect grid);  missed, other, back :
    int, rays that met nothing, a non-receiver, a receiver's back side.
    """

    rays: int
    points: int
    point: np.ndarray
    texel: np.ndarray
    target: np.ndarray
    missed: int = 0
    other: int = 0
    back: int = 0

    def figures(self) -> dict:
        total = max(self.rays * self.points, 1)
        return {"rays_per_point": self.rays, "points": self.points,
                "front_hits": round(len(self.point) / total, 5),
                "missed": round(self.missed / total, 5), "other_objects": round(
                    self.other / total, 5), "back_sides": round(self.back / total, 5)}


def gather(nearest, origins, normals, geometric, rays: int, seed: int, vertices, triangles,
           receiver, triangle_uv, t_side: int, t_offsets, g_side: int, g_maps,
           block: int = 1 << 18) -> Gather:
    """Cast ``rays`` cosine-weighted rays about ``normals`` from every gather point.

    Parameters
    ----------
    nearest : callable ``(origins (M, 3), dirs (M, 3)) -> (triangle (M,), distance (M,))``
        The ray engine's nearest-hit query (:meth:`..rays.engine.Occluder.nearest`), over
        ``vertices`` (N, 3) / ``triangles`` (T, 3).
    origins, normals, geometric : (P, 3) ray origins (already off the surface), shading normals
        and geometric normals of the gather points (rays below the geometric plane add nothing).
    seed : the Cranley-Patterson shifts' seed (one shift per gather point).
    receiver : (T,) int the receiver each triangle belongs to, -1 for other casters.
    triangle_uv : (T, 3, 2) UVs of each triangle's corners (receivers' rows are read).
    t_side, t_offsets : T's side and each receiver's first stacked texel column.
    g_side, g_maps : the indirect grid's side and per receiver a (g_side**2,) int64 map from a
        texel to its gather point (stacked), -1 where the grid does not cover it.
    """
    O = np.asarray(origins, np.float64)
    P = len(O)
    K = int(rays)
    shifts = np.random.default_rng(seed).random((P, 2))
    V = np.asarray(vertices, np.float64)
    Tri = np.asarray(triangles, np.int64)
    recv = np.asarray(receiver, np.int64)
    tuv = np.asarray(triangle_uv, np.float64)
    Vt = V[Tri]
    Ng_tri = np.cross(Vt[:, 1] - Vt[:, 0], Vt[:, 2] - Vt[:, 0])
    out = {"point": [], "texel": [], "target": []}
    missed = other = back = 0
    per = max(1, block // K)
    for a in range(0, P, per):
        b = min(a + per, P)
        d = cosine_directions(np.asarray(normals, np.float64)[a:b], K, shifts[a:b])   # (n,K,3)
        up = np.einsum("pkj,pj->pk", d, np.asarray(geometric, np.float64)[a:b]) > 0
        pid = np.repeat(np.arange(a, b), K)[up.ravel()]
        dd = d.reshape(-1, 3)[up.ravel()]
        oo = O[pid]
        tri, dist = nearest(oo, dd)
        hit = tri >= 0
        missed += int((~hit).sum()) + int((~up).sum())
        r = np.where(hit, recv[np.maximum(tri, 0)], -1)
        is_recv = hit & (r >= 0)
        other += int((hit & ~is_recv).sum())
        front = is_recv & (np.einsum("mj,mj->m", Ng_tri[np.maximum(tri, 0)], dd) < 0)
        back += int((is_recv & ~front).sum())
        k = np.nonzero(front)[0]
        if not k.size:
            continue
        bary = hit_barycentrics(V, Tri, tri[k], oo[k], dd[k], dist[k])
        uv = np.einsum("mc,mcj->mj", bary, tuv[tri[k]])
        rk = r[k]
        tex = uv_texel(uv, t_side) + np.asarray(t_offsets, np.int64)[rk]
        gt = uv_texel(uv, g_side)
        target = np.full(len(k), -1, np.int64)
        for ri, gmap in enumerate(g_maps):
            m = rk == ri
            target[m] = np.asarray(gmap, np.int64)[gt[m]]
        out["point"].append(pid[k])
        out["texel"].append(tex)
        out["target"].append(target)
    cat = {n: (np.concatenate(v) if v else np.zeros(0, np.int64)) for n, v in out.items()}
    return Gather(K, P, cat["point"], cat["texel"], cat["target"], missed, other, back)


def indirect(g: Gather, T, albedo_t, bounces: int = 2) -> np.ndarray:
    """``I`` (3, S, P) float32 (module docstring) from T's rows ``T`` (S, n_t) -- float32 or
    float16, stacked receivers' texels -- with the albedo (n_t, 3) at T's texels (each hit
    reflects with the albedo at its texel), over ``bounces`` >= 1. One sparse product per
    bounce and colour (a row sums at most to 1)."""
    if bounces < 1:
        raise ValueError(f"need bounces >= 1, got {bounces}")
    Tt = np.ascontiguousarray(np.asarray(T).T, dtype=np.float32)              # (n_t, S)
    n_t, S = Tt.shape
    out = np.zeros((3, S, g.points), np.float32)
    for c in range(3):
        out[c] = _bounced(*_bounce_matrices(g, albedo_t, n_t, c), Tt, bounces).T
    return out


def _bounce_matrices(g: Gather, albedo_t, n_t: int, c: int):
    """The sparse one-bounce gather (P, n_t) and grid-to-grid bounce (P, P) of colour ``c``."""
    from scipy import sparse

    a = np.asarray(albedo_t, np.float32)[:, c]
    ok = g.target >= 0
    G1 = sparse.csr_matrix((a[g.texel] / g.rays, (g.point, g.texel)), shape=(g.points, n_t))
    G2 = sparse.csr_matrix((a[g.texel[ok]] / g.rays, (g.point[ok], g.target[ok])),
                           shape=(g.points, g.points))
    return G1, G2


def _bounced(G1, G2, X, bounces: int):
    """``sum_{i < bounces} G2^i G1 X``: ``bounces`` bounces of light gathered from the direct
    light ``X`` (n_t, m) at T's texels; (P, m) in X's dtype."""
    level = np.asarray(G1 @ X)
    total = level.copy()
    for _ in range(bounces - 1):
        level = np.asarray(G2 @ level)
        total += level
    return total


def indirect_pca(g: Gather, T, albedo_t, bounces: int = 2, components: int = 16,
                 oversample: int = 8, power: int = 1, seed: int = 0, chunk: int = 256,
                 measure: bool = False):
    """The top ``components`` of ``I`` over directions (the rows of :func:`indirect`, colours
    and gather points as columns) without forming ``I``: a randomised SVD (Halko et al. 2011,
    ``power`` subspace iterations) whose products with ``I`` and its transpose are the bounce
    operator ``B_c = sum_i G2^i G1`` and its adjoint applied to a few images, and T read once per
    pass in chunks of ``chunk`` directions (float32 from a half-float store).

    Returns ``(V, U, kept)``: coefficients V (S, k) float32 and images U (k, 3, P) float32 with
    ``I[c, s] ~ sum_j V[s, j] U[j, c]``, and with ``measure`` the share of ``||I||^2`` they
    keep (one more pass that bounces all of T: the cost of :func:`indirect`), else None."""
    if bounces < 1 or components < 1:
        raise ValueError(f"need bounces >= 1 and components >= 1; got {bounces}, {components}")
    T = np.asarray(T) if not hasattr(T, "shape") else T
    S, n_all = T.shape
    m = min(S, int(components) + int(oversample))
    # B reads T only at the texels the gather rays met: the products run over those columns
    # (the statue demo at 512^2: 51 % of T's texels; the bumps at 256^2: 66 %), the same sums
    # without the zeros. T's products are float32 (T is stored in half floats; against
    # float64 products the term moved by 5e-7 relative on the statue at 512^2, and the pass
    # took 3.8 s instead of 5.2), accumulated over chunks and decomposed in float64
    cols = np.unique(g.texel)
    g = replace(g, texel=np.searchsorted(cols, g.texel))
    albedo_t = np.asarray(albedo_t, np.float32)[cols]
    n_t = len(cols)

    def rows(a):                         # T's directions a:a + chunk at the met texels, float32
        return np.asarray(T[a:a + chunk])[:, cols].astype(np.float32)
    mats = [_bounce_matrices(g, albedo_t, n_t, c) for c in range(3)]

    def apply(X):                        # (n_t, m) float64 -> (3, P, m): B_c X
        return np.stack([_bounced(G1, G2, X, bounces) for G1, G2 in mats])

    def adjoint(Y):                      # (3, P, m) -> (n_t, m): sum_c B_c^T Y_c
        acc = np.zeros((n_t, Y.shape[-1]))
        for (G1, G2), y in zip(mats, Y):
            z, s = y, y.copy()
            for _ in range(bounces - 1):
                z = np.asarray(G2.T @ z, np.float64)
                s += z
            acc += np.asarray(G1.T @ s, np.float64)
        return acc

    def t_times(W):                      # T (S, n_t) @ W (n_t, m) -> (S, m)
        W = W.astype(np.float32)
        return np.concatenate([rows(a) @ W for a in range(0, S, chunk)]).astype(np.float64)

    def t_transposed(O):                 # T^T (n_t, S) @ O (S, m) -> (n_t, m)
        acc = np.zeros((n_t, O.shape[1]))
        for a in range(0, S, chunk):
            acc += rows(a).T @ O[a:a + chunk].astype(np.float32)
        return acc

    def orth(Y):                         # (3, P, m) -> orthonormal columns, same shape
        q, _ = np.linalg.qr(Y.reshape(-1, Y.shape[-1]))
        return q.reshape(Y.shape)

    omega = np.random.default_rng(seed).standard_normal((S, m))
    Q = orth(apply(t_transposed(omega)))             # range of I^T (images)
    for _ in range(int(power)):
        C = t_times(adjoint(Q))                       # I Q: (S, m)
        Q = orth(apply(t_transposed(C)))
    C = t_times(adjoint(Q))                           # I ~ C Q^T
    Uc, sv, Vt = np.linalg.svd(C, full_matrices=False)
    k = min(int(components), m)
    V = (Uc[:, :k] * sv[:k]).astype(np.float32)
    U = np.einsum("cpm,km->kcp", Q, Vt[:k]).astype(np.float32)
    if not measure:
        return V, U, None
    total = 0.0                          # ||I||^2: B applied to all of T
    for a in range(0, S, chunk):
        Tc = rows(a).T                                                        # (n_t, s)
        total += float(np.sum(apply(Tc) ** 2))
    kept = float(np.sum(sv[:k] ** 2) / total) if total > 0 else 1.0
    return V, U, kept
