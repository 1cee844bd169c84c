"""Error of transport bases versus coefficient count (Nowrouzezahrai et al. 2008, Fig. 10).

For a sampled transport ``T`` (V, S) and test lightings, each basis keeps ``k`` coefficients per
vertex and is scored by

``transport_rel``
    Solid-angle-weighted (sphere L2) relative error ``sqrt(sum (T - T_k)^2 dw) /
    sqrt(sum T^2 dw)`` over all vertices -- the paper's "L2 norm over the reconstructed transport
    functions". ``transport_rel_unweighted`` drops the ``dw`` (the sample-space norm that PCA
    minimises; equal for equal-area sets such as Halton).
``shading_rel_max`` / ``shading_rel_mean``
    Relative RMS error over vertices (and channels) of ``B_k = T_k . Lw`` against ``T . Lw``, the
    worst and the mean over the test lightings (albedo cancels).

Bases at ``k`` coefficients: eigentransport with ``d = k`` (plus the shared mean, one global
vector); real SH of the largest order with ``(l + 1)^2 <= k`` (weighted least squares, the best
SH fit in the sphere-L2 norm); Haar on the cubemap keeping the ``k`` largest coefficients per
vertex (needs a ``cube:n`` set). In all three the shading of the reconstruction is what a
renderer would compute from the coefficients (see each module), so ``shading_rel`` is exact.

Also here: a synthetic shadowed scene (:func:`synthetic_shadowed_transport`, spheres over a
ground plane, ``T = visibility x cosine`` by exact ray-sphere tests) and a sun-and-sky test
environment (:func:`sun_sky_environment`), so the comparison can be reproduced without Blender.
All results are plain dicts/lists (JSON-safe).
"""

from __future__ import annotations

import numpy as np

from ..sphere.directions import DirectionSet
from .eigentransport import fit_eigentransport
from ..sphere.haar_baseline import haar_approximate
from ..sphere.hemisphere import equirect_pixel_directions, normalize_directions
from ..sphere.sh_baseline import sh_order_for_count, sh_project, sh_reconstruct

BASES = ("eigentransport", "sh", "haar")


# ----------------------------------------------------------------------------------------------
# synthetic data


def synthetic_shadowed_transport(direction_set: DirectionSet, n_vertices: int = 300,
                                 n_occluders: int = 6, seed: int = 0,
                                 sphere_fraction: float = 0.3,
                                 max_tilt_deg: float = 25.0) -> dict:
    """Visibility x cosine transport of random spheres standing over a ground plane.

    Vertices: ``(1 - sphere_fraction)`` of them on the ground ``z = 0`` in ``[-1, 1]^2`` with
    normals tilted up to ``max_tilt_deg`` from +z (a bumpy ground), the rest on the sphere
    surfaces (not inside another sphere). Occluders: the spheres (centres in ``[-1, 1]^2`` at
    height 0.15..0.6, radii 0.12..0.35) and the infinite ground plane (``z < 0`` is blocked
    for every vertex). ``T[v, j] = V(x_v, w_j) max(0, n_v . w_j)`` with exact ray-sphere tests.

    Returns
    -------
    dict
        ``T`` (V, S) float64, ``positions`` (V, 3), ``normals`` (V, 3) unit,
        ``centres`` (K, 3), ``radii`` (K,).
    """
    rng = np.random.default_rng(seed)
    V = int(n_vertices)
    if V < 1:
        raise ValueError(f"n_vertices must be >= 1, got {n_vertices}")
    centres = np.column_stack([rng.uniform(-1, 1, n_occluders), rng.uniform(-1, 1, n_occluders),
                               rng.uniform(0.15, 0.6, n_occluders)])
    radii = rng.uniform(0.12, 0.35, n_occluders)
    n_sph = int(round(V * sphere_fraction)) if n_occluders else 0
    n_gnd = V - n_sph
    pos = [np.column_stack([rng.uniform(-1, 1, (n_gnd, 2)), np.zeros(n_gnd)])]
    tilt = np.radians(max_tilt_deg) * np.sqrt(rng.uniform(0, 1, n_gnd))
    az = rng.uniform(0, 2 * np.pi, n_gnd)
    nrm = [np.column_stack([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])]
    owner = [np.full(n_gnd, -1)]
    got = 0
    while got < n_sph:               # rejection: above ground, outside the other spheres
        k = rng.integers(0, n_occluders, 4 * n_sph)
        u = normalize_directions(rng.normal(size=(4 * n_sph, 3)))
        p = centres[k] + radii[k, None] * u
        dist = np.linalg.norm(p[:, None, :] - centres[None], axis=2)
        dist[np.arange(len(k)), k] = np.inf
        ok = (p[:, 2] > 1e-3) & np.all(dist > radii[None], axis=1)
        take = np.nonzero(ok)[0][: n_sph - got]
        pos.append(p[take]), nrm.append(u[take]), owner.append(k[take])
        got += take.size
    positions = np.concatenate(pos)
    normals = np.concatenate(nrm)
    owner = np.concatenate(owner)
    w = direction_set.directions
    cosine = np.clip(normals @ w.T, 0.0, None)                        # (V, S)
    visible = np.broadcast_to(w[:, 2] >= 0.0, cosine.shape).copy()   # the ground plane
    origin = positions + 1e-9 * normals
    for k in range(n_occluders):
        oc = origin - centres[k]                                        # (V, 3)
        b = oc @ w.T                                                    # (V, S)
        c = np.sum(oc * oc, axis=1) - radii[k] ** 2                     # (V,)
        disc = b * b - c[:, None]
        t_far = -b + np.sqrt(np.clip(disc, 0.0, None))
        hit = (disc > 0) & (t_far > 0) & (c[:, None] > 0)
        hit[owner == k] = False          # a convex sphere never shadows itself (cosine does)
        visible &= ~hit
    return {"T": cosine * visible, "positions": positions, "normals": normals,
            "centres": centres, "radii": radii}


def sun_sky_environment(height: int, sun_direction, *, row_order: str, width: int | None = None,
                        sun_radiance: float = 2000.0, sun_radius_deg: float = 4.0,
                        sky_radiance=(0.25, 0.35, 0.6), ground_radiance=(0.05, 0.04, 0.03)
                        ) -> np.ndarray:
    """A simple HDR equirect environment: graded sky, dark ground and a soft sun disc.

    Parameters
    ----------
    height : int
        Image rows (width defaults to ``2 * height``).
    sun_direction : array_like, shape (3,)
    row_order : {"top_first", "bottom_first"}
    sun_radiance : float
        Peak sun radiance (W m^-2 sr^-1); the disc is a Gaussian of angular radius
        ``sun_radius_deg`` (soft, so bilinear lookups are smooth).

    Returns
    -------
    ndarray, shape (height, width, 3), float64 radiance
    """
    width = 2 * height if width is None else width
    d = equirect_pixel_directions(height, width, row_order=row_order)
    s = normalize_directions(sun_direction).reshape(3)
    z = d[..., 2:3]
    sky = np.asarray(sky_radiance) * (0.4 + 0.6 * np.clip(z, 0, 1))
    img = np.where(z >= 0, sky, np.asarray(ground_radiance))
    ang = np.arccos(np.clip(d @ s, -1, 1))
    img = img + sun_radiance * np.exp(-0.5 * (ang / np.radians(sun_radius_deg)) ** 2)[..., None]
    return img


# ----------------------------------------------------------------------------------------------
# error curves


def _weighted_rel(T, T_rec, w) -> float:
    num = float(np.sum((T - T_rec) ** 2 * w))
    den = float(np.sum(T * T * w))
    return float(np.sqrt(num / den)) if den > 0 else (0.0 if num == 0 else float("inf"))


def _shading_errors(T, T_rec, envs) -> tuple[float, float]:
    """Worst and mean relative RMS shading error over envs (K, S, C)."""
    errs = []
    for e in envs:
        ref = T @ e
        nr = float(np.linalg.norm(ref))
        ne = float(np.linalg.norm(T_rec @ e - ref))
        errs.append((0.0 if ne == 0 else float("inf")) if nr == 0 else ne / nr)
    return float(np.max(errs)), float(np.mean(errs))


def error_curves(T, direction_set: DirectionSet, envs, counts=(4, 9, 16, 25, 36, 49),
                 bases=BASES) -> dict:
    """Transport and shading error of each basis versus per-vertex coefficient count.

    Parameters
    ----------
    T : array_like, shape (V, S)
    direction_set : DirectionSet
        The directions ``T`` was sampled at (``cube:n`` needed for Haar; otherwise Haar is
        reported as skipped).
    envs : array_like, shape (K, S) or (K, S, C)
        Weighted test lightings (radiance x solid angle).
    counts : sequence of int
        Per-vertex coefficient counts.
    bases : sequence of {"eigentransport", "sh", "haar"}

    Returns
    -------
    dict (JSON-safe)
        ``{"counts", "direction_set", "n_vertices", "n_environments", <basis>: {
        "coefficients", "transport_rel", "transport_rel_unweighted", "shading_rel_max",
        "shading_rel_mean", ...}}``; eigentransport adds ``captured_energy`` and ``rank``,
        SH adds ``order``; a skipped basis is ``{"skipped": reason}``.
    """
    T = np.asarray(T, dtype=np.float64)
    S = direction_set.size
    if T.ndim != 2 or T.shape[1] != S:
        raise ValueError(f"T must have shape (V, {S}), got {T.shape}")
    e = np.asarray(envs, dtype=np.float64)
    e = e[None] if e.ndim == 1 else e
    if e.shape[1] != S:
        raise ValueError(f"envs must have shape (K, {S}) or (K, {S}, C), got {e.shape}")
    e = e.reshape(e.shape[0], S, -1)
    counts = [int(c) for c in counts]
    if any(c < 1 for c in counts):
        raise ValueError(f"counts must be >= 1, got {counts}")
    unknown = set(bases) - set(BASES)
    if unknown:
        raise ValueError(f"unknown bases {sorted(unknown)}; expected some of {BASES}")
    w = direction_set.solid_angles
    ones = np.ones(S)
    out = {"counts": counts, "direction_set": direction_set.spec, "n_vertices": int(T.shape[0]),
           "n_environments": int(e.shape[0])}

    def _row(T_rec):
        smax, smean = _shading_errors(T, T_rec, e)
        return _weighted_rel(T, T_rec, w), _weighted_rel(T, T_rec, ones), smax, smean

    def _collect(recs, extra):
        res = {"coefficients": [], "transport_rel": [], "transport_rel_unweighted": [],
               "shading_rel_max": [], "shading_rel_mean": []}
        for k, T_rec in recs:
            a, b, c, d = _row(T_rec)
            res["coefficients"].append(int(k))
            res["transport_rel"].append(a)
            res["transport_rel_unweighted"].append(b)
            res["shading_rel_max"].append(c)
            res["shading_rel_mean"].append(d)
        res.update(extra)
        return res

    if "eigentransport" in bases:
        model = fit_eigentransport(T, d=max(counts))
        recs, energy = [], []
        for c in counts:
            sub = model.truncate(min(c, model.d))
            recs.append((sub.d, sub.reconstruct()))
            energy.append(sub.captured_energy)
        out["eigentransport"] = _collect(recs, {"captured_energy": energy, "rank": model.rank})
    if "sh" in bases:
        recs, orders = [], []
        for c in counts:
            l = sh_order_for_count(c)
            coef = sh_project(T, direction_set.directions, w, l, method="lstsq")
            recs.append(((l + 1) ** 2, sh_reconstruct(coef, direction_set.directions)))
            orders.append(l)
        out["sh"] = _collect(recs, {"order": orders})
    if "haar" in bases:
        if direction_set.kind != "cube":
            out["haar"] = {"skipped": f"Haar needs a cube:n direction set, got "
                                      f"{direction_set.spec}"}
        else:
            recs = [(min(c, S), haar_approximate(T, direction_set, c)) for c in counts]
            out["haar"] = _collect(recs, {})
    return out
