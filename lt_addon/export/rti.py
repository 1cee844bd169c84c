"""Reflectance Transformation Imaging (RTI) models of a relightable texture (bpy-free).

An RTI model gives each texel a few coefficients of a fixed basis over the light direction;
the relit value is their dot product with the basis at the light. Two bases the RTI field
uses, in the conventions of the ``relight`` tools of CNR-ISTI Visual Computing Lab (whose
files the OpenLIME web viewer reads):

* PTM (Malzbender et al. 2001), 6 terms in the light's image-plane components (lu, lv):
  ``1, lu, lv, lu^2, lu lv, lv^2``;
* HSH (hemispherical harmonics, Gautron et al. 2004), 4, 9 or 16 terms
  (orders 2, 3, 4), orthonormal on the upper hemisphere; exports write 4 or 9 (OpenLIME
  evaluates 9 and would drop terms 10-16 silently).

The light frame is the bake's: z up (the hemisphere the transport texture samples), lu = x
(texture right for a plane facing +z with the usual UVs), lv = y (texture up).

Fitting is weighted least squares over the baked light directions (weights: the samples'
solid angles, so the fit minimises the error integrated over the hemisphere), in float64,
with the design matrix's condition number checked. Storage quantises each coefficient to 8
bits with a per-coefficient ``scale`` and ``bias`` (``c = (q / 255 - bias) * scale``), as the
relight format's planes do.
"""

from __future__ import annotations

import math

import numpy as np

TYPES = {"ptm": 6, "hsh": 9}
#: Refuse a fit whose weighted design matrix is worse conditioned than this.
MAX_CONDITION = 1e6


def ptm_basis(light) -> np.ndarray:
    """PTM terms at unit light directions: (..., 3) -> (..., 6), in the relight tools' order
    ``1, lu, lv, lu^2, lu lv, lv^2`` (the .ptm file's order is reversed; OpenLIME reads
    this one)."""
    l = np.asarray(light, np.float64)
    u, v = l[..., 0], l[..., 1]
    return np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1)


def _assoc_legendre(l: int, m: int, x: np.ndarray) -> np.ndarray:
    """P_l^m(x) with the Condon-Shortley phase, m >= 0 (the recurrence of Numerical Recipes)."""
    pmm = np.ones_like(x)
    if m > 0:
        somx2 = np.sqrt(np.clip((1.0 - x) * (1.0 + x), 0.0, None))
        fact = 1.0
        for _ in range(m):
            pmm = -pmm * fact * somx2
            fact += 2.0
    if l == m:
        return pmm
    pmmp1 = x * (2 * m + 1) * pmm
    if l == m + 1:
        return pmmp1
    pll = pmmp1
    for ll in range(m + 2, l + 1):
        pll = ((2 * ll - 1) * x * pmmp1 - (ll + m - 1) * pmm) / (ll - m)
        pmm, pmmp1 = pmmp1, pll
    return pll


#: HSH's light is clamped to this elevation (rad) -- OpenLIME's ``HSH.minElevation``
#: (src/ShaderRTI.js at 5b4e27b). The relight tools' own fitter clamps at 0.01 rad; a
#: different clamp from the viewer's shows another image below it (measured: 46 levels at
#: the horizon), so the fit, our page and OpenLIME all use this one.
HSH_MIN_ELEVATION = 0.15


def hsh_basis(light, order: int = 3) -> np.ndarray:
    """Hemispherical harmonics at unit light directions: (..., 3) -> (..., order^2).

    Gautron et al. 2004: with ``x = 2 cos(theta) - 1`` and
    ``K_l^m = sqrt((2l+1)(l-|m|)! / (2 pi (l+|m|)!))``, the m = 0 term is ``K P_l^0(x)``,
    m > 0 is ``sqrt(2) K cos(m phi) P_l^m(x)`` and m < 0 is ``sqrt(2) K sin(|m| phi)
    P_l^|m|(x)`` (P with the Condon-Shortley phase). In the relight tools' (and OpenLIME's)
    conventions each order l lists m = +l ... -l, every m != 0 term is negated, and theta is
    clamped at ``pi/2 - HSH_MIN_ELEVATION`` (their 9 terms reproduced exactly; the 16-term
    extension follows the same rule). Orthonormal over the upper hemisphere."""
    if order not in (2, 3, 4):
        raise ValueError(f"HSH order must be 2, 3 or 4 ({order * order} terms), got {order}")
    l3 = np.asarray(light, np.float64)
    theta = np.minimum(np.arccos(np.clip(l3[..., 2], -1.0, 1.0)),
                       np.pi / 2 - HSH_MIN_ELEVATION)
    x = 2.0 * np.cos(theta) - 1.0
    phi = np.arctan2(l3[..., 1], l3[..., 0])
    out = []
    for l in range(order):
        for m in range(l, -l - 1, -1):
            am = abs(m)
            k = math.sqrt((2 * l + 1) * math.factorial(l - am)
                          / (2 * math.pi * math.factorial(l + am)))
            p = _assoc_legendre(l, am, x)
            if m == 0:
                out.append(k * p)
            elif m > 0:
                out.append(-math.sqrt(2.0) * k * np.cos(m * phi) * p)
            else:
                out.append(-math.sqrt(2.0) * k * np.sin(am * phi) * p)
    return np.stack(out, axis=-1)


def basis(kind: str, light, terms: int | None = None) -> np.ndarray:
    """The basis of ``kind`` ('ptm' or 'hsh') with ``terms`` terms (hsh: 4, 9 or 16)."""
    if kind == "ptm":
        if terms not in (None, 6):
            raise ValueError("PTM has 6 terms")
        return ptm_basis(light)
    if kind == "hsh":
        terms = 9 if terms is None else int(terms)
        order = int(round(math.sqrt(terms)))
        if order * order != terms:
            raise ValueError(f"HSH has 4, 9 or 16 terms, got {terms}")
        return hsh_basis(light, order)
    raise ValueError(f"unknown RTI basis {kind!r}; one of ptm, hsh")


def fit(values, lights, weights, kind: str, terms: int | None = None) -> np.ndarray:
    """Weighted least-squares coefficients of ``kind`` per texel and channel.

    Parameters
    ----------
    values : (S, P, C) relit values at the S lights
    lights : (S, 3) unit light directions (upper hemisphere)
    weights : (S,) positive sample weights (solid angles, sr)

    Returns
    -------
    (P, K, C) float64 coefficients.

    Raises
    ------
    ValueError
        If the weighted design matrix's condition number exceeds MAX_CONDITION (too few or
        too clustered lights for the basis).
    """
    B = basis(kind, lights, terms)                                   # (S, K)
    sw = np.sqrt(np.asarray(weights, np.float64))[:, None]
    Bw = B * sw
    cond = np.linalg.cond(Bw)
    if not np.isfinite(cond) or cond > MAX_CONDITION:
        raise ValueError(f"{kind} with {B.shape[1]} terms is ill-conditioned on these "
                         f"{B.shape[0]} lights (condition number {cond:.3g})")
    v = np.asarray(values, np.float64)
    S, P, C = v.shape
    coef, *_ = np.linalg.lstsq(Bw, (v * sw[:, :, None]).reshape(S, P * C), rcond=None)
    return coef.reshape(B.shape[1], P, C).transpose(1, 0, 2)


def evaluate(coeffs, light, kind: str) -> np.ndarray:
    """Relit values (P, C) at one light direction from coefficients (P, K, C)."""
    b = basis(kind, np.asarray(light, np.float64), coeffs.shape[1])
    return np.einsum("k,pkc->pc", b, coeffs)


def quantize(coeffs):
    """8-bit planes of coefficients (P, K, C): ``q`` (P, K, C) uint8 and per-(K, C)
    ``scale`` and ``bias`` with ``c = (q / 255 - bias) * scale``.

    Each (coefficient, channel) spans its own [min, max]; the rounding error of a coefficient
    is at most ``scale / 510``."""
    c = np.asarray(coeffs, np.float64)
    lo, hi = c.min(axis=0), c.max(axis=0)                            # (K, C)
    scale = np.where(hi > lo, hi - lo, 1.0)
    bias = -lo / scale
    q = np.clip(np.rint((c / scale + bias) * 255.0), 0, 255).astype(np.uint8)
    return q, scale, bias


def dequantize(q, scale, bias) -> np.ndarray:
    """Coefficients (P, K, C) float64 from 8-bit planes (the viewer's arithmetic)."""
    return (np.asarray(q, np.float64) / 255.0 - bias) * scale


def to_display(linear, exposure: float) -> np.ndarray:
    """sRGB-encoded display values in [0, 1] of linear radiance times ``exposure`` (what a
    camera's image of the surface would hold; RTI models are fitted to such images)."""
    x = np.clip(np.asarray(linear, np.float64) * exposure, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def rmse_psnr(estimate, truth) -> tuple[float, float]:
    """RMSE and PSNR (dB, peak 1) of display values in [0, 1]."""
    e = float(np.sqrt(np.mean((np.asarray(estimate, np.float64)
                               - np.asarray(truth, np.float64)) ** 2)))
    return e, (float("inf") if e == 0 else float(20.0 * np.log10(1.0 / e)))


def check_lights(kind: str, lights) -> np.ndarray:
    """Lights (S', 3) a fit must stay non-negative at: the fitted ``lights`` plus two rings of
    72 azimuths, on the horizon and (HSH) at its clamp elevation -- every light a viewer can
    show is one of these or between them (HSH shows the clamp ring below it)."""
    az = np.radians(np.arange(72) * 5.0)
    els = [0.0] + ([HSH_MIN_ELEVATION] if kind == "hsh" else [])
    rings = [np.stack([np.cos(e) * np.cos(az), np.cos(e) * np.sin(az),
                       np.full(az.shape, np.sin(e))], axis=1) for e in els]
    return np.concatenate([np.asarray(lights, np.float64), *rings])


#: Below this the relit display value of a fit is raised (1/4 of an 8-bit level): OpenLIME
#: turns display values to linear with ``pow(v, 2.2)`` (src/Shader.js ``srgb2linear``),
#: undefined in GLSL for v < 0, so a fit must not go negative where the light can be.
NONNEGATIVE_MARGIN = 0.25 / 255.0


def keep_nonnegative(coef, kind: str, lights, weights, *, penalty: float = 10.0,
                     iterations: int = 6, chunk: int = 4096, lift_residual: bool = True):
    """Coefficients (P, K, C) whose relight is >= NONNEGATIVE_MARGIN at every
    :func:`check_lights` light, changed only where it was not.

    The weighted least-squares fit ``x`` of a texel and channel minimises
    ``sum_s w_s (v_s - b_s . x)^2``; where it dips below the margin (ringing at grazing light,
    where the truth is 0 or near it) it is refitted with a penalty on the dipping lights,
    ``+ mu sum_(s in A) w_s (b_s . x - margin)^2`` (A grows over a few iterations), which
    keeps the fit close to the data elsewhere. The normal equations need no data: the
    unconstrained fit's right-hand side is ``G0 x`` with ``G0 = B^T W B``. A residual dip is
    then lifted through the constant term. float64 throughout; ``G`` is K x K (K <= 16) and
    positive definite (G0 is, by the fit's conditioning check).

    Returns (coef, stats): how many (texel, channel) curves were refitted and lifted, and the
    largest lift (display units).
    """
    coef = np.array(coef, np.float64, copy=True)
    P, K, C = coef.shape
    lights = np.asarray(lights, np.float64)
    w = np.asarray(weights, np.float64)
    B = basis(kind, lights, K)
    G0 = (B * w[:, None]).T @ B
    chk = check_lights(kind, lights)
    Bc = basis(kind, chk, K)                                             # (Sc, K)
    wc = np.concatenate([w, np.full(chk.shape[0] - w.size, w.mean())])
    b0 = float(Bc[0, 0])                                                 # the constant term
    m = NONNEGATIVE_MARGIN
    refitted, lifted, top = 0, 0, 0.0
    for a in range(0, P, chunk):
        x = coef[a:a + chunk].transpose(0, 2, 1).reshape(-1, K)          # (n C, K)
        pred = x @ Bc.T                                                  # (n C, Sc)
        bad = np.flatnonzero((pred < m).any(axis=1))
        if bad.size == 0:
            continue
        xb = x[bad]
        rhs0 = xb @ G0
        active = pred[bad] < m
        for _ in range(iterations):
            aw = active * (penalty * wc)[None, :]                        # (b, Sc)
            G = G0[None] + np.einsum("bs,sk,sl->bkl", aw, Bc, Bc)
            rhs = rhs0 + m * (aw @ Bc)
            xb = np.linalg.solve(G, rhs[:, :, None])[:, :, 0]
            p2 = xb @ Bc.T
            grow = (p2 < m) & ~active
            if not grow.any():
                break
            active |= grow
        low = (xb @ Bc.T).min(axis=1)
        lift = np.where(low < m, (m - low) / b0, 0.0) if lift_residual else np.zeros(low.shape)
        xb[:, 0] += lift
        refitted += bad.size
        lifted += int(np.count_nonzero(lift))
        top = max(top, float((lift * b0).max()))
        x[bad] = xb
        coef[a:a + chunk] = x.reshape(-1, C, K).transpose(0, 2, 1)
    return coef, {"refitted_curves": refitted, "lifted_curves": lifted,
                  "max_lift": round(top, 6), "check_lights": int(chk.shape[0])}
