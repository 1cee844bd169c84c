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


#: Bytes of T (half floats) one window of texel columns reads: the PCA's working set per step.
WINDOW_BYTES = 64 << 20
#: Met texels whose products with T are gathered into the images at once (one sparse product per
#: colour; fewer, larger products are faster, each holds FLUSH_TEXELS x m float32).
FLUSH_TEXELS = 1 << 20


def indirect_pca(g: Gather, T, albedo_t, bounces: int = 2, components: int = 16,
                 oversample: int = 8, power: int = 1, seed: int = 0, chunk: int = 256,
                 measure: bool = False, window: int | None = None, tail: float | None = None,
                 most: int | None = None, figures: dict | None = None):
    """The top ``components`` of ``I`` over directions (the rows of :func:`indirect`, colours
    and gather points as columns) without forming ``I``: a randomised SVD (Halko et al. 2011,
    ``power`` subspace iterations) whose products with ``I`` and its transpose are the bounce
    operator ``B_c = sum_i G2_c^i G1_c`` and its adjoint applied to a few images.

    ``T`` (S, n) is read once per pass by windows of ``window`` texel columns (default:
    :data:`WINDOW_BYTES` of half floats; an object with ``columns(lo, hi)`` is asked for them,
    else ``T[:, lo:hi]``), only at the texels the gather rays met. Per pass the working set is
    one window (S x window), at most :data:`FLUSH_TEXELS` x m products and the images (3, P, m)
    in float64; what grows with the texture's side is a few numbers per met texel (at most one
    per hit). Until 2026-12-04 T was read by chunks of directions whose products (met texels x
    m, float64) were accumulated in full: on the statue demo's gather at 1024^2 (12.3 M hits,
    1.5 M met texels, 443 k points) 71.9 s and 2,170 MiB above the start, now 43.2 s and
    1,639 MiB, the term equal to 1.4e-6 relative.

    ``G1_c = G A_c``: the hits' counts per (point, texel) over K (one sparse matrix shared by the
    colours) times the albedo at the texel; ``G2_c`` (P, P) per colour.

    Returns ``(V, U, kept)``: coefficients V (S, k) float32 and images U (k, 3, P) float32 with
    ``I[c, s] ~ sum_j V[s, j] U[j, c]``, and with ``measure`` the share of ``||I||^2`` they
    keep (one more pass that bounces all of T by ``chunk`` directions: the cost of
    :func:`indirect`), else None.

    With ``tail`` the count grows as the scene needs: where the sketch's singular values past
    the ``components``-th hold more than ``tail`` of its RMS (``sqrt(sum_{j>=k} s_j^2 /
    sum_j s_j^2)``), the sketch is made again with twice the components, up to ``most``, and
    the smallest count whose tail is within ``tail`` is kept (never fewer than
    ``components``). The sketch sees ``oversample`` values past the count, so a tail it shows
    is a floor of the true one. ``figures`` (a dict) receives the sketches' counts and the
    kept count's tail."""
    if bounces < 1 or components < 1:
        raise ValueError(f"need bounces >= 1 and components >= 1; got {bounces}, {components}")
    T = np.asarray(T) if not hasattr(T, "shape") else T
    S, n_all = T.shape
    P = int(g.points)
    # the term's rank is at most min(S, 3 P) (the images' QR needs 3 P >= m)
    rank = min(S, 3 * P)
    m = min(rank, int(components) + int(oversample))
    cols = np.unique(g.texel)                         # the met texels, sorted (n_t,)
    n_t = len(cols)
    alb = np.asarray(albedo_t, np.float32)[cols]      # (n_t, 3)
    G = _gather_matrix(g, cols)                       # (P, n_t) CSC, float32
    G2 = _grid_matrices(g, np.asarray(albedo_t, np.float32))   # per colour (P, P) CSR
    W = int(window) if window else max(1, WINDOW_BYTES // (2 * S))
    # windows of T's columns [lo, hi) holding met texels, and their met texels cols[a:b]
    edges = np.arange(0, n_all + W, W)
    cuts = np.searchsorted(cols, edges)
    spans = [(int(edges[i]), int(min(edges[i + 1], n_all)), int(cuts[i]), int(cuts[i + 1]))
             for i in range(len(edges) - 1) if cuts[i + 1] > cuts[i]]

    held = {}

    def window_rows(lo, hi, a, b):                    # T[:, cols[a:b]] float32 (S, b - a)
        if lo in held:
            return held[lo]
        block = T.columns(lo, hi) if hasattr(T, "columns") else T[:, lo:hi]
        rows = np.asarray(block)[:, cols[a:b] - lo].astype(np.float32)
        if len(spans) == 1:
            # one window holds every met texel: read and converted once for the four passes
            # (each pass held this array while it ran anyway; the bumps demo at 256^2 read
            # it four times, 0.76 s of its 1.15 s PCA)
            held[lo] = rows
        return rows

    def bounce(Y):                                    # Y_c <- sum_i G2_c^i Y_c, in place
        for c in range(3):
            level = Y[c]
            for _ in range(bounces - 1):
                level = np.asarray(G2[c] @ level)
                Y[c] += level
        return Y

    def apply_t(O):                                   # B T^T O: (S, m) -> (3, P, m)
        O = np.asarray(O, np.float32)
        k = O.shape[1]
        Y = np.zeros((3, P, k))
        X = np.empty((min(n_t, FLUSH_TEXELS + W), k), np.float32)   # T^T O at met texels
        first = 0                                     # X[0] is met texel `first`

        def flush(upto):                              # Y_c += G1_c X over [first, upto)
            for c in range(3):
                Y[c] += G[:, first:upto] @ (alb[first:upto, c, None] * X[:upto - first])

        for lo, hi, a, b in spans:
            if b - first > len(X):
                flush(a)
                first = a
            X[a - first:b - first] = window_rows(lo, hi, a, b).T @ O
        flush(n_t)
        return bounce(Y)

    def t_adjoint(Q):                                 # T B^T Q: (3, P, m) -> (S, m)
        k = Q.shape[-1]
        S3 = np.empty((P, 3, k))                      # sum_i (G2_c^T)^i Q_c, points first
        for c in range(3):
            S3[:, c] = level = Q[c]
            for _ in range(bounces - 1):
                level = np.asarray(G2[c].T @ level)
                S3[:, c] += level
        S3 = S3.reshape(P, -1)
        C = np.zeros((S, k))
        for lo, hi, a, b in spans:
            Z = np.asarray(G[:, a:b].T @ S3).reshape(b - a, 3, k)             # (b - a, 3, m)
            Z = np.einsum("tc,tcm->tm", alb[a:b], Z).astype(np.float32)
            C += window_rows(lo, hi, a, b) @ Z
        return C

    def orth(Y):                         # (3, P, m) -> orthonormal columns, same shape
        q, _ = np.linalg.qr(Y.reshape(-1, Y.shape[-1]))
        return q.reshape(Y.shape)

    def sketch(m):
        omega = np.random.default_rng(seed).standard_normal((S, m))
        Q = orth(apply_t(omega))                      # range of I^T (images)
        for _ in range(int(power)):
            C = t_adjoint(Q)
            del Q                                     # (not held while the next is made)
            Q = orth(apply_t(C))
        C = t_adjoint(Q)                              # I ~ C Q^T
        return (Q, *np.linalg.svd(C, full_matrices=False))

    def tail_at(sv, k):                               # the sketch's RMS past k, relative
        e = sv.astype(np.float64) ** 2
        return float(np.sqrt(e[k:].sum() / e.sum())) if e.sum() > 0 else 0.0

    k = min(int(components), m)
    Q, Uc, sv, Vt = sketch(m)
    tried = [k]
    if tail is not None:
        cap = min(rank, int(most or components))
        while tail_at(sv, k) > tail and k < cap:
            k = min(cap, 2 * k)
            m = min(rank, k + int(oversample))
            del Q, Uc, Vt                             # (not held while the next is made)
            Q, Uc, sv, Vt = sketch(m)
            tried.append(k)
        # the fewest components (from the asked count up) whose tail is within ``tail``
        k = next((j for j in range(min(int(components), k), k) if tail_at(sv, j) <= tail), k)
    held.clear()
    if figures is not None:
        figures.update(sketches=tried, tail=round(tail_at(sv, k), 4), components=int(k))
    V = (Uc[:, :k] * sv[:k]).astype(np.float32)
    U = np.einsum("cpm,km->kcp", Q, Vt[:k]).astype(np.float32)
    if not measure:
        return V, U, None
    total = 0.0                          # ||I||^2: B applied to all of T, by directions
    g_t = replace(g, texel=np.searchsorted(cols, g.texel))
    mats = [_bounce_matrices(g_t, alb, n_t, c) for c in range(3)]
    for a in range(0, S, chunk):
        Tc = np.asarray(T[a:a + chunk])[:, cols].astype(np.float32).T          # (n_t, s)
        total += float(sum(np.sum(_bounced(G1, G2c, Tc, bounces) ** 2) for G1, G2c in mats))
    kept = float(np.sum(sv[:k] ** 2) / total) if total > 0 else 1.0
    return V, U, kept


def _gather_matrix(g: Gather, cols) -> "sparse.csc_matrix":
    """(P, n_t) CSC float32: the share of each point's K rays that met each met texel
    (``cols``, sorted): ``G1_c = G diag(albedo_c at cols)``."""
    from scipy import sparse

    t = np.searchsorted(cols, g.texel)
    G = sparse.csc_matrix((np.full(len(t), 1.0 / g.rays, np.float32), (g.point, t)),
                          shape=(g.points, len(cols)))
    G.sum_duplicates()
    return G


def _grid_matrices(g: Gather, albedo_t) -> list:
    """The grid-to-grid bounce (P, P) CSR float32 of each colour (a hit reflects with the
    albedo at its texel), sharing one index structure."""
    from scipy import sparse

    ok = g.target >= 0
    P = int(g.points)
    key = g.point[ok].astype(np.int64) * P + g.target[ok]
    uniq, inv = np.unique(key, return_inverse=True)
    rows, idx = np.divmod(uniq, P)
    indices = idx.astype(np.int32 if P < 2**31 else np.int64)
    indptr = np.searchsorted(rows, np.arange(P + 1)).astype(indices.dtype)
    a = np.asarray(albedo_t, np.float32)[g.texel[ok]] / g.rays                 # (H', 3)
    out = []
    for c in range(3):
        data = np.bincount(inv.ravel(), weights=a[:, c], minlength=len(uniq)).astype(np.float32)
        out.append(sparse.csr_matrix((data, indices, indptr), shape=(P, P), copy=False))
    return out
