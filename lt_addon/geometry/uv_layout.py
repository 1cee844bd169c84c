"""UV layout checks before a texture bake: coverage and overlap of UV triangles.

A texture bake writes each texel from the face whose UV triangle covers it; where UV islands
overlap, faces overwrite each other and the relit texture mixes unrelated surfaces. These
checks count, per texel centre, how many UV triangles cover it.
"""

from __future__ import annotations

import numpy as np


def uv_coverage(triangles, resolution: int) -> np.ndarray:
    """How many UV triangles cover each texel centre.

    Parameters
    ----------
    triangles : array_like, shape (F, 3, 2)
        UV coordinates of each triangle's corners (any real values; only [0, 1]^2 counts).
    resolution : int
        Texels per side; texel ``(i, j)`` has its centre at ``((j + 0.5) / R, (i + 0.5) / R)``
        (row ``i`` along v, bottom first).

    Returns
    -------
    counts : ndarray, shape (R, R), int32
        Number of triangles containing the texel centre (nudged by ~3e-4 texel so shared
        edges count once; degenerate, zero-area triangles cover nothing).
    """
    tri = np.asarray(triangles, dtype=np.float64)
    if tri.ndim != 3 or tri.shape[1:] != (3, 2):
        raise ValueError(f"triangles must have shape (F, 3, 2), got {tri.shape}")
    if not np.all(np.isfinite(tri)):
        raise ValueError("UV coordinates contain NaN or inf")
    r = int(resolution)
    if r < 1:
        raise ValueError(f"resolution must be >= 1, got {resolution}")
    counts = np.zeros((r, r), dtype=np.int32)
    # texel-index space (centre of texel j at x = j), shifted by a tiny generic offset so a
    # centre never lies exactly on an edge shared by two triangles (it would count twice)
    p = tri * r - 0.5 - np.array([3.14159e-4, 2.71828e-4])
    lo = np.clip(np.ceil(p.min(axis=1) - 1e-9), 0, r - 1).astype(int)
    hi = np.clip(np.floor(p.max(axis=1) + 1e-9), 0, r - 1).astype(int)
    a, b, c = p[:, 0], p[:, 1], p[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    inside_box = (p.max(axis=1) >= 0).all(axis=1) & (p.min(axis=1) <= r - 1).all(axis=1)
    for f in np.nonzero((np.abs(area) > 1e-12) & inside_box)[0]:
        xs = np.arange(lo[f, 0], hi[f, 0] + 1)
        ys = np.arange(lo[f, 1], hi[f, 1] + 1)
        if xs.size == 0 or ys.size == 0:
            continue
        X, Y = np.meshgrid(xs, ys)
        s = np.sign(area[f])
        w0 = s * ((b[f, 0] - X) * (c[f, 1] - Y) - (b[f, 1] - Y) * (c[f, 0] - X))
        w1 = s * ((c[f, 0] - X) * (a[f, 1] - Y) - (c[f, 1] - Y) * (a[f, 0] - X))
        w2 = s * ((a[f, 0] - X) * (b[f, 1] - Y) - (a[f, 1] - Y) * (b[f, 0] - X))
        inside = (w0 > 0) & (w1 > 0) & (w2 > 0)
        counts[Y[inside], X[inside]] += 1
    return counts


def uv_overlap_report(triangles, resolution: int = 256) -> dict:
    """Covered and overlapping fractions of the texels (JSON-safe).

    Returns
    -------
    dict
        ``covered`` (fraction of texel centres inside at least one triangle), ``overlapping``
        (fraction covered by two or more, out of the covered ones), ``resolution``.
    """
    counts = uv_coverage(triangles, resolution)
    covered = int(np.count_nonzero(counts))
    overlapping = int(np.count_nonzero(counts > 1))
    return {"resolution": int(resolution), "covered": covered / counts.size,
            "overlapping": overlapping / covered if covered else 0.0}
