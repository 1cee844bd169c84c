"""Per-vertex light transport baked with Cycles (bpy), Nowrouzezahrai et al. 2008.

``T[v, s]`` is the response of vertex ``v`` to a distant light of unit normal irradiance from
sample direction ``s``: ``V(x, w_s) max(0, n . w_s)`` with ``bounces = 0`` (visibility times
cosine), plus the interreflected light with ``bounces > 0``. One Cycles vertex bake per
direction under a hard Sun lamp (angle 0, strength 1): direct light from a hard Sun is
noise-free at 1 sample (one shadow ray), so ``bounces = 0`` needs 1 sample; interreflection is
Monte Carlo and needs more. Not used: packing three directions into one bake as red, green and
blue suns -- Cycles picks one light per path, so the channels get noisy (DESIGN.md sec. 4).

The DIFFUSE bake without the colour pass gives ``E / pi`` (irradiance over pi) per vertex with
smooth shading; we store ``T = pi * value``, so ``E = sum_s L_s T[:, s] dw_s`` and the shading of
an albedo-``rho`` diffuse surface is ``rho / pi * E``.

Like the texture bake this is a generator yielding progress and returning the result, so the
operator, CLI and tests drive the same code, and stopping it restores the scene.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .cycles_bake import BakeInputError, EnvironmentBake, check_bakeable


@dataclass
class TransportBakeResult:
    transport: np.ndarray  # (V, S) float32
    directions: np.ndarray  # (S, 3) float64, world frame
    cycles_seconds: float
    total_seconds: float
    bake_calls: int


@dataclass
class Progress:
    done: int
    total: int
    message: str


def bake_transport(scene, obj, directions, bounces: int = 0, samples: int | None = None,
                   seed: int = 0):
    """Generator: bake ``T`` of ``obj`` for every direction; returns a TransportBakeResult.

    Parameters
    ----------
    directions : ndarray, shape (S, 3)
        Unit vectors towards the light, world frame (z up).
    bounces : int
        Diffuse bounces; 0 = visibility x cosine only.
    samples : int, optional
        Cycles samples per vertex; default 1 without bounces (exact), 64 with bounces.

    Yields
    ------
    Progress after every direction.
    """
    check_bakeable(obj, need_uv=False)
    dirs = np.asarray(directions, dtype=np.float64)
    if dirs.ndim != 2 or dirs.shape[1] != 3 or len(dirs) == 0:
        raise BakeInputError(f"directions must have shape (S, 3), got {dirs.shape}")
    if not np.all(np.isfinite(dirs)):
        raise BakeInputError("directions contain NaN or inf")
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    if samples is None:
        samples = 1 if bounces == 0 else 64
    n_vertices = len(obj.data.vertices)
    if n_vertices * len(dirs) * 4 > 8 * 2 ** 30:
        raise BakeInputError(f"{n_vertices} vertices x {len(dirs)} directions needs more than "
                             "8 GiB; use fewer directions")
    start = time.perf_counter()
    T = np.empty((n_vertices, len(dirs)), dtype=np.float32)
    with EnvironmentBake(scene, obj, None, samples, bounces, (8, 16), mode="irradiance",
                         seed=seed, world_sampling="none") as session:
        for s, d in enumerate(dirs):
            T[:, s] = np.pi * session.bake_sun(d, 1.0, 0.0)[:, 0]
            yield Progress(s + 1, len(dirs), f"direction {s + 1}/{len(dirs)}")
        cycles, calls = session.bake_seconds, session.bake_calls
    return TransportBakeResult(T, dirs, cycles, time.perf_counter() - start, calls)


def bake_environment_truth(scene, obj, environment, bounces: int, samples: int,
                           seed: int = 1) -> np.ndarray:
    """Cycles ground truth: ``E / pi`` per vertex under an equirect environment (bottom row first).

    Returns
    -------
    values : ndarray, shape (V, 3), float32
        Irradiance over pi per vertex (a white Lambertian surface's outgoing radiance).
    """
    env = np.asarray(environment)
    with EnvironmentBake(scene, obj, None, samples, bounces, env.shape[:2], mode="irradiance",
                         seed=seed, world_sampling="importance") as session:
        return session.bake(env)
