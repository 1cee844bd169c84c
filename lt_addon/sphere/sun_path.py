"""Directions along an animated sun's path, on top of a hemisphere set (bpy-free).

A sun of 2 degrees needs baked directions about 0.4 degrees apart to relight its shadows without
ghosts; a whole hemisphere that dense is ~250,000 directions, but an animated Sun only ever
stands on one curve. :func:`with_path` adds directions every ``step`` degrees along that curve to
a coarser base set; the solid angle of every direction (what an environment relight weights it
by) comes from the spherical Voronoi cells of the union, cut at the horizon.
"""

from __future__ import annotations

import numpy as np

from .directions import DirectionSet


def densify(path, step_deg: float) -> np.ndarray:
    """Points along a polyline of unit directions (F, 3), at most ``step_deg`` apart on great
    circles between consecutive samples, above the horizon only; (M, 3) float64."""
    P = np.asarray(path, np.float64).reshape(-1, 3)
    P = P / np.maximum(np.linalg.norm(P, axis=1, keepdims=True), 1e-30)
    step = np.radians(float(step_deg))
    if not step > 0:
        raise ValueError(f"the sun-path step must be > 0 degrees, got {step_deg}")
    out = [P[:1]]
    for a, b in zip(P[:-1], P[1:]):
        ang = float(np.arccos(np.clip(a @ b, -1.0, 1.0)))
        n = int(np.ceil(ang / step))
        if n == 0:
            continue
        t = np.arange(1, n + 1) / n
        if ang < 1e-9:
            seg = np.repeat(b[None], n, 0)
        else:                                   # slerp
            s = np.sin(ang)
            seg = (np.sin((1 - t) * ang)[:, None] * a + np.sin(t * ang)[:, None] * b) / s
        out.append(seg)
    pts = np.concatenate(out)
    return pts[pts[:, 2] > 0.0]


def upper_voronoi_areas(dirs) -> np.ndarray:
    """Solid angles (S,) of the spherical Voronoi cells of upper-hemisphere directions (S, 3),
    cut at the horizon (the set mirrored below it closes the cells); they sum to 2 pi."""
    from scipy.spatial import SphericalVoronoi

    D = np.asarray(dirs, np.float64)
    mirrored = D * np.array([1.0, 1.0, -1.0])
    both = np.concatenate([D, mirrored])
    sv = SphericalVoronoi(both, radius=1.0, threshold=1e-9)
    areas = sv.calculate_areas()[:len(D)]
    return areas * (2.0 * np.pi / areas.sum())


def band(pts, step_deg: float, width_deg: float) -> np.ndarray:
    """Parallel copies of a densified path (M, 3) offset sideways by multiples of ``step_deg``
    up to ``width_deg / 2`` on either side (a sun disc on the path reaches that far off it)."""
    k = int(np.floor(width_deg / 2.0 / step_deg + 1e-9))
    if k <= 0 or len(pts) < 2:
        return pts
    t = np.gradient(pts, axis=0)                              # along the path
    side = np.cross(pts, t)
    side /= np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-30)
    out = [pts]
    for j in range(1, k + 1):
        a = np.radians(j * step_deg)
        for sgn in (1.0, -1.0):
            out.append(pts * np.cos(a) + sgn * side * np.sin(a))
    allp = np.concatenate(out)
    return allp[allp[:, 2] > 0.0]


def with_path(base: DirectionSet, path, step_deg: float = 0.5,
              width_deg: float = 0.0) -> DirectionSet:
    """``base`` (upper hemisphere) plus directions every ``step_deg`` along ``path`` (F, 3: the
    sun's directions over its animation, in order), in a band ``width_deg`` wide (0: the curve
    alone); base directions closer than one step to them are dropped (they would duplicate
    them). Kind ``custom``; ``params`` say where each part came from."""
    pts = band(densify(path, step_deg), step_deg, width_deg)
    if not len(pts):
        return base
    cos_step = np.cos(np.radians(step_deg))
    near = (base.directions @ pts.T).max(axis=1) > cos_step
    keep = base.directions[~near]
    dirs = np.concatenate([keep, pts])
    # two path samples closer than a hundredth of the step would make a degenerate cell
    _, first = np.unique(np.round(dirs / (np.radians(step_deg) / 100.0)), axis=0,
                         return_index=True)
    dirs = dirs[np.sort(first)]
    n_path = int(len(dirs) - len(keep))
    el = np.degrees(np.arcsin(np.clip(pts[:, 2], -1, 1)))
    return DirectionSet(dirs, upper_voronoi_areas(dirs), "custom",
                        {"base": base.spec, "base_kept": int(len(keep)),
                         "base_dropped": int(near.sum()), "sun_path_step_deg": float(step_deg),
                         "sun_path_directions": n_path,
                         "sun_path_elevation_deg": [round(float(el.min()), 2),
                                                    round(float(el.max()), 2)]})
