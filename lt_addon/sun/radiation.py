"""Solar radiation maps from a transport bake (bpy-free): kWh/m^2 per texel over a study.

A texel's T at a baked direction is ``cos x V / pi`` under a unit hard sun (its irradiance
over pi). Under a clear sky (:mod:`.clear_sky`), over the study's instants ``i`` (each standing
for ``dt_i`` hours):

- **beam**: ``sum_i DNI_i dt_i pi T(s_i)``, T relit at the Sun's direction ``s_i`` with the bake's
  kernel (as the viewport and :mod:`.sunlight_hours` relight it). The relight is linear in T,
  so the whole study is one weighted sum of T's rows: ``pi (W^T b) . T``, ``W`` the suns' kernel
  weights over the baked directions and ``b_r`` the DNI-hours of the study's suns with direction
  ``r`` -- one pass over T whatever the number of instants;
- **diffuse**: an isotropic sky of radiance ``DHI / pi``: ``sum_i DHI_i dt_i x F``, with the
  texel's ``F = sum_d a_d T_d`` over the baked directions (``a_d`` their solid angles, scaled so
  that an unobstructed horizontal texel gets ``F = 1``: it receives DHI): the sky it sees,
  cosine-weighted -- its sky view factor;
- **total** = beam + diffuse. Light reflected by the ground and other surfaces, the circumsolar
  brightening and the horizon band of a real sky are not modelled; T holds direct light only.

Units: kWh/m^2 over the study (W/m^2 x hours / 1000). Checked against a brute-force ray count
of the same beam and the sky view factor by rays (tests/blender/test_sun_study.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import clear_sky


@dataclass
class RadiationMap:
    """One object's radiation over a study, each (R, R) float32 kWh/m^2 (row 0 at v = 0, 0 on
    texels the bake did not fill): ``beam``, ``diffuse``, ``total``; ``covered`` (R, R) bool;
    ``sky_view`` (R, R) float32 (the diffuse factor F); ``horizontal_kwh``: what an unobstructed
    horizontal surface gets over the study (``beam``, ``diffuse``, ``total``: the scale of the
    maps); ``seconds``."""

    beam: np.ndarray
    diffuse: np.ndarray
    total: np.ndarray
    covered: np.ndarray
    sky_view: np.ndarray
    horizontal_kwh: dict
    seconds: float = 0.0

    def summary(self) -> dict:
        t = self.total[self.covered]
        if not t.size:
            return {"texels": 0}
        return {"texels": int(t.size), "min_kwh_m2": round(float(t.min()), 3),
                "mean_kwh_m2": round(float(t.mean()), 3), "max_kwh_m2": round(float(t.max()), 3),
                "horizontal_kwh_m2": {k: round(v, 3) for k, v in self.horizontal_kwh.items()}}


def study_irradiance(suns, times, *, linke_turbidity: float = 3.0, altitude_m: float = 0.0):
    """``(dni, dhi, hours)`` per instant of ``times`` (a StudyTimes): clear-sky W/m^2 at the
    Sun of ``suns`` (a StudySuns: refracted elevation, so apparent zenith) and the hours each
    instant stands for (0 where the Sun is down)."""
    from .solar_position import posix_seconds

    posix = posix_seconds(times.utc)
    doy = np.array([_day_of_year(p) for p in posix], np.float64)
    zen = 90.0 - np.asarray(suns.elevation, np.float64)
    _, dni, dhi = clear_sky.ineichen(zen, doy, linke_turbidity, altitude_m)
    step = times.step_h if times.step_h is not None else 1.0
    hours = np.where(suns.up, float(step), 0.0)
    return dni, dhi, hours


def _day_of_year(posix: float) -> float:
    import datetime as _dt

    t = _dt.datetime.fromtimestamp(float(posix), _dt.timezone.utc)
    return t.timetuple().tm_yday + (t.hour + t.minute / 60.0 + t.second / 3600.0) / 24.0


def radiation_map(store, suns, dni, dhi, hours, *, sun_angle_deg: float = 0.0,
                  kernel: str = "linear", covered=None) -> RadiationMap:
    """The :class:`RadiationMap` of one object's ``store`` (a TransportStore) over the study:
    ``suns`` a StudySuns, ``dni``/``dhi`` (N,) W/m^2 and ``hours`` (N,) per instant
    (:func:`study_irradiance`); ``covered`` (R, R) the texels the bake filled (default: where
    the sky view is > 0)."""
    import time

    from .sunlight_hours import sun_weight_matrix

    t0 = time.perf_counter()
    dset = store.directions
    up = np.asarray(suns.up, bool)
    idx = np.asarray(suns.index)[up]
    b = np.bincount(idx, weights=(np.asarray(dni) * np.asarray(hours))[up],
                    minlength=len(suns.directions))                     # Wh/m^2 per sun
    diffuse_wh = float((np.asarray(dhi) * np.asarray(hours))[up].sum())
    S = len(dset.directions)
    u = np.zeros(S)
    if len(suns.directions):
        W = sun_weight_matrix(dset, suns.directions, sun_angle_deg, kernel)   # (M, S)
        u = np.asarray(W.T @ b).ravel()
    a = np.asarray(dset.solid_angles, np.float64) * (dset.directions[:, 2] > 0)
    # scaled so that an unobstructed horizontal texel (T = max(z, 0) / pi) sees F = 1
    a = a / max(float((a * np.maximum(dset.directions[:, 2], 0.0)).sum() / np.pi), 1e-12)
    both = store.relight_dense(np.stack([np.pi * u, a], axis=1)).astype(np.float64)
    beam = both[..., 0] / 1000.0
    sky = both[..., 1]
    diffuse = sky * diffuse_wh / 1000.0
    if covered is None:
        covered = sky > 0
    z = np.asarray(suns.directions, np.float64)[:, 2] if len(suns.directions) else np.zeros(0)
    horizontal = {"beam": float((b * np.maximum(z, 0.0)).sum() / 1000.0),
                  "diffuse": diffuse_wh / 1000.0}
    horizontal["total"] = horizontal["beam"] + horizontal["diffuse"]
    cov = np.asarray(covered, bool)
    f32 = lambda x: np.where(cov, x, 0.0).astype(np.float32)  # noqa: E731
    return RadiationMap(f32(beam), f32(diffuse), f32(beam + diffuse), cov, f32(sky),
                        horizontal, time.perf_counter() - t0)
