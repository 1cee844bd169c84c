"""Directional lightmaps (L1 spherical harmonics, MonoSH) fitted from a transport texture
(bpy-free).

Game engines store baked light *directionally* so that a normal map still responds: per
texel, the L1 spherical-harmonic projection of the incident radiance (Godot's LightmapGI in
directional mode, Unity/Bakery "SH"), or its MonoSH reduction (an RGB L0 and one monochrome
L1 vector). A direction-sampled transport texture holds what that projection needs.

Conventions (all arrays float64 unless stated):

* real SH, Sloan's order and constants, in the frame of the directions given:
  ``Y00 = 0.282095``, ``Y1-1 = 0.488603 y``, ``Y10 = 0.488603 z``, ``Y11 = 0.488603 x``;
  coefficients ``L[..., 4, 3]`` (texel, coefficient, RGB) of incident radiance
  (W m^-2 sr^-1 for a light of unit strength);
* the irradiance a surface of normal ``n`` gets from them is
  ``E(n) = pi L00 Y00 + (2 pi / 3) sum_m L1m Y1m(n)`` (Ramamoorthi & Hanrahan 2001's
  clamped-cosine convolution, truncated at l = 1), and the outgoing radiance of a white
  Lambertian surface is ``E / pi`` -- what Godot's shader adds as ambient light
  (``0.282095 L0 + 0.32573 (L1 . n)``, 0.32573 = 0.488603 * 2/3).

From transport: ``T[s, p]`` is ``E/pi`` under a unit sun from ``w_s`` (see
:mod:`..transport.texture`), i.e. ``V(p, w_s) max(0, n_p . w_s) / pi`` for direct light. With the
texel's baked normal ``n_p`` the visibility is ``V = pi T / (n_p . w_s)``, clipped to [0, 1]
(grazing samples, ``n . w < COS_MIN``, are taken as 0: a 1e-3 share of the hemisphere).
Cycles' hard-sun direct bake carries no sampling noise, so the division is safe above that. Light below the texel's tangent plane is
blocked by the surface itself, so V = 0 there. Bounce light (baked as the irradiance it adds
at the geometric normal) is taken to arrive uniformly over the texel's upper hemisphere.
"""

from __future__ import annotations

import numpy as np

Y0 = 0.5 * np.sqrt(1.0 / np.pi)            # 0.282095
Y1 = np.sqrt(3.0 / (4.0 * np.pi))          # 0.488603
#: Clamped-cosine convolution factors A_l (Ramamoorthi & Hanrahan 2001).
A0, A1 = np.pi, 2.0 * np.pi / 3.0
#: Below this cosine to the baked normal the visibility is not recovered from ``V cos / pi``.
COS_MIN = 1e-3


def sh_basis(directions) -> np.ndarray:
    """L1 real SH at unit directions: (..., 3) -> (..., 4) in the order 00, 1-1, 10, 11."""
    d = np.asarray(directions, np.float64)
    return np.stack([np.full(d.shape[:-1], Y0), Y1 * d[..., 1], Y1 * d[..., 2],
                     Y1 * d[..., 0]], axis=-1)


def visibility(T, directions, normals) -> np.ndarray:
    """Per texel and direction visibility ``V = pi T / cos`` in [0, 1].

    Parameters
    ----------
    T : (S, P) array, ``E/pi`` per unit sun (direct light)
    directions : (S, 3) unit directions of the samples
    normals : (P, 3) unit normals of the texels, in the directions' frame

    Returns
    -------
    (S, P) float64; 0 where ``n . w < COS_MIN``.
    """
    cos = np.asarray(directions, np.float64) @ np.asarray(normals, np.float64).T   # (S, P)
    ok = cos >= COS_MIN
    V = np.where(ok, np.pi * np.asarray(T, np.float64) / np.where(ok, cos, 1.0), 0.0)
    return np.clip(V, 0.0, 1.0)


def project(T, directions, radiance_weights, normals, indirect=None) -> np.ndarray:
    """L1 SH of the incident radiance per texel.

    Parameters
    ----------
    T : (S, P) transport (``E/pi`` per unit sun)
    directions : (S, 3)
    radiance_weights : (S,) or (S, 3)
        ``L(w_s) dw_s`` of the lighting (W m^-2 per sample; an environment's quadrature
        weights, or a sun's normalised interpolation kernel times its strength).
    normals : (P, 3) unit texel normals
    indirect : (P, 3) or None
        Bounce irradiance over pi (``E_ind / pi``) at the texel's normal under the same light;
        spread uniformly over the texel's hemisphere.

    Returns
    -------
    (P, 4, 3) float64 SH coefficients of incident radiance.
    """
    w = np.asarray(radiance_weights, np.float64)
    w = np.repeat(w[:, None], 3, axis=1) if w.ndim == 1 else w                    # (S, 3)
    V = visibility(T, directions, normals)                                          # (S, P)
    Y = sh_basis(directions)                                                        # (S, 4)
    # L[p, k, c] = sum_s V[s, p] Y[s, k] w[s, c]
    L = np.einsum("sp,sk,sc->pkc", V, Y, w, optimize=True)
    if indirect is not None:
        L += np.pi * hemisphere_sh(normals)[:, :, None] * np.asarray(indirect, np.float64)[:, None, :]
    return L


def hemisphere_sh(normals) -> np.ndarray:
    """SH (P, 4) of radiance ``1/pi`` over the hemisphere around each normal: its irradiance
    at the normal is 1, so ``hemisphere_sh(n) * E`` carries irradiance ``E`` uniformly.

    ``int_H Y00 = 2 pi Y0``, ``int_H Y1(w) dw = pi Y1 n``."""
    n = np.asarray(normals, np.float64)
    return np.concatenate([np.full(n.shape[:-1] + (1,), 2.0 * np.pi * Y0),
                           np.pi * Y1 * n[..., [1, 2, 0]]], axis=-1) / np.pi


def irradiance(L, normals) -> np.ndarray:
    """Irradiance (P, 3) a surface of normal ``normals`` (P, 3) gets from SH ``L`` (P, 4, 3)."""
    Y = sh_basis(normals)                                                          # (P, 4)
    conv = np.array([A0, A1, A1, A1])
    return np.einsum("pk,pkc->pc", Y * conv, L)


def reference_irradiance(T, directions, radiance_weights, normals, tilted, indirect=None):
    """Irradiance (P, 3) at tilted normals from the transport itself: ``sum_s w_s V_s
    max(0, n' . w_s)`` plus the bounce light's uniform hemisphere seen at the tilt,
    ``E_ind (1 + n . n') / 2``. This is what our own relight gives a normal-mapped surface."""
    w = np.asarray(radiance_weights, np.float64)
    w = np.repeat(w[:, None], 3, axis=1) if w.ndim == 1 else w
    V = visibility(T, directions, normals)
    cos_t = np.clip(np.asarray(directions, np.float64) @ np.asarray(tilted, np.float64).T, 0, None)
    E = np.einsum("sp,sc->pc", V * cos_t, w)
    if indirect is not None:
        nn = np.einsum("pi,pi->p", normals, tilted)
        E += np.pi * np.asarray(indirect, np.float64) * (1.0 + nn)[:, None] / 2.0
    return E


#: Rec. 709 luminance weights (MonoSH's one direction is the luminance's).
LUMA = np.array([0.2126, 0.7152, 0.0722])
#: "Ready to apply" factors: ``E(n)/pi = K0 L00 + K1 (L1 . n)`` with the L1 vector (x, y, z).
K0, K1 = Y0, Y1 * 2.0 / 3.0


def to_monosh(L):
    """Bakery's MonoSH encoding of SH (P, 4, 3): ``L0`` (P, 3), the ready-to-apply RGB term
    ``K0 L00`` (so that ``E/pi = L0 + n . L1``), and ``direction`` (P, 3) in [0, 1]:
    ``L1_luma / (2 L0_luma) * 0.5 + 0.5`` with ``L1 = K1 (L11, L1-1, L10)`` (x, y, z), clipped
    to [0, 1] (|L1| <= 2 L0 per component, as the 8-bit texture holds)."""
    L = np.asarray(L, np.float64)
    L0 = K0 * L[:, 0, :]
    l1 = K1 * np.stack([L[:, 3], L[:, 1], L[:, 2]], axis=1) @ LUMA          # (P, 3) xyz
    l0 = L0 @ LUMA
    d = np.where(l0[:, None] > 0, l1 / (2.0 * np.where(l0 > 0, l0, 1.0))[:, None], 0.0)
    return L0, np.clip(d * 0.5 + 0.5, 0.0, 1.0)


def from_monosh(L0, direction) -> np.ndarray:
    """SH (P, 4, 3) back from :func:`to_monosh`'s pair, as Bakery's shader decodes it:
    ``L1_c = (2 direction - 1) * 2 L0_c`` -- each channel's L1 is the luminance direction
    scaled by that channel's L0."""
    L0 = np.asarray(L0, np.float64)
    l1 = (2.0 * np.asarray(direction, np.float64) - 1.0)[:, :, None] * 2.0 * L0[:, None, :]
    L = np.empty((L0.shape[0], 4, 3))
    L[:, 0] = L0 / K0
    L[:, 3], L[:, 1], L[:, 2] = l1[:, 0] / K1, l1[:, 1] / K1, l1[:, 2] / K1
    return L


def tilted_normals(normals, tilt_deg: float, azimuth_deg: float) -> np.ndarray:
    """Normals (P, 3) tilted by ``tilt_deg`` towards azimuth ``azimuth_deg`` about each
    normal's own tangent frame (a normal map's perturbation)."""
    n = np.asarray(normals, np.float64)
    helper = np.where(np.abs(n[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(helper, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    a, p = np.radians(tilt_deg), np.radians(azimuth_deg)
    return np.cos(a) * n + np.sin(a) * (np.cos(p) * t + np.sin(p) * b)
