"""Ground truth for steerable textures: Cycles bakes of the same light, and of a Sun lamp (bpy).

Three references per light direction ``w0`` (all in the calibrated units of
:meth:`SteerableTexture.relight`, i.e. a light of unit normal irradiance times ``intensity``):

``same_light``      a Cycles bake under the environment image of the *same* steered light
                    (``environment_image`` x calibration gain) at the bake's samples but another
                    seed: measures what bake noise and storage cost (the method is exact here).
``same_light_4x``   the same at 4x the samples (closer to the noise-free truth).
``sun``             a Cycles Sun lamp of the same strength with the angular diameter of the
                    steered lobe's half-maximum region: the approximation cost users care about.
"""

from __future__ import annotations

import math

import numpy as np

from ...lt_addon.sphere.hemisphere import hemisphere_to_disk, normalize_directions
from ...lt_addon.io.storage import reconstruction_error
from ...lt_addon.steerable.basis import environment_image, light_profile_2d
from ..base.cycles_bake import EnvironmentBake
from ..base.jobs import Progress


def equivalent_sun_angle_deg(texture) -> float:
    """Angular diameter (degrees) of a disc with the steered lobe's half-maximum solid angle."""
    omega = light_profile_2d(texture.basis, (0.0, 0.0))["half_max_solid_angle_sr"]
    return math.degrees(2.0 * math.acos(1.0 - omega / (2.0 * math.pi)))


def steered_light_environment(texture, direction, env_height: int, intensity: float = 1.0):
    """Equirectangular image (bottom row first) of the calibrated steered light towards ``direction``.

    Returns
    -------
    env : ndarray, shape (env_height, 2 * env_height), float32
    """
    d = normalize_directions(np.asarray(direction, dtype=np.float64).reshape(3))
    _, gain = texture.steering_weights(d)
    if d[2] < 0:
        return np.zeros((env_height, 2 * env_height), dtype=np.float32)
    env = environment_image(texture.basis, hemisphere_to_disk(d), env_height, 2 * env_height,
                            row_order="bottom_first", dtype=np.float64)
    return (env * gain * intensity).astype(np.float32)


def ground_truth(scene, obj, texture, directions, samples: int, bounces: int, mode: str,
                 env_height: int, seed: int = 0, world_sampling: str = "importance",
                 with_4x: bool = True, with_sun: bool = True):
    """Generator: yields :class:`.jobs.Progress`; returns a list of per-direction dicts.

    Each dict has ``direction``, ``azimuth``/``elevation`` (degrees) and ``errors``:
    ``{"same_light": {...}, "same_light_4x": {...}, "sun": {...}}`` with the metrics of
    :func:`..lt_addon.io.storage.reconstruction_error` (``rel_fro`` is the relative RMSE), plus
    ``images``: relit (clamped), same_light (the 4x-sample truth when computed) and sun arrays.
    """
    r = texture.resolution
    sun_angle = equivalent_sun_angle_deg(texture)
    steps = len(directions) * (1 + int(with_4x) + int(with_sun))
    done = 0
    results = []
    truth_seed = seed + 7919  # independent noise from the basis bakes
    plans = [("same_light", samples)] + ([("same_light_4x", 4 * samples)] if with_4x else [])
    images = {name: [] for name, _ in plans}
    for name, spp in plans:
        with EnvironmentBake(scene, obj, r, spp, bounces, (env_height, 2 * env_height), mode=mode,
                             seed=truth_seed, world_sampling=world_sampling) as session:
            for d in directions:
                images[name].append(session.bake(steered_light_environment(texture, d, env_height)))
                done += 1
                yield Progress(done, steps, f"{name} truth {len(images[name])}/{len(directions)}")
    suns = []
    if with_sun:
        with EnvironmentBake(scene, obj, r, 4 * samples, bounces, (env_height, 2 * env_height),
                             mode=mode, seed=truth_seed, world_sampling=world_sampling) as session:
            for d in directions:
                suns.append(session.bake_sun(d, 1.0, sun_angle))
                done += 1
                yield Progress(done, steps, f"sun truth {len(suns)}/{len(directions)}")
    for i, d in enumerate(directions):
        d = normalize_directions(np.asarray(d, dtype=np.float64))
        relit_raw = texture.relight(d, clamp=False)
        relit = texture.relight(d)
        errors = {name: reconstruction_error(images[name][i], relit_raw) for name, _ in plans}
        if with_sun:
            errors["sun"] = reconstruction_error(suns[i], relit)
        results.append({
            "direction": d.tolist(),
            "azimuth": math.degrees(math.atan2(d[1], d[0])),
            "elevation": math.degrees(math.asin(max(-1.0, min(1.0, d[2])))),
            "errors": errors,
            "images": {"relit": relit,
                       "same_light": images["same_light_4x" if with_4x else "same_light"][i],
                       **({"sun": suns[i]} if with_sun else {})},
        })
    return {"sun_angle_deg": sun_angle, "directions": results}


def contact_sheet(rows: list[dict], path: str, max_rows: int = 4) -> dict:
    """PNG: per light direction, steered | Cycles truth (same light) | |difference| x 4 | Sun,
    each panel captioned (light, error) -- in UV space, the fallback picture where the scene
    has no camera (:func:`.compare_render.report_comparison` is the camera-space one).

    ``rows`` are the per-direction dicts of :func:`ground_truth` (with ``images``). One
    exposure for the whole sheet maps the 99th percentile of the truths to white.
    """
    from ...lt_addon.io.contact_sheet import linear_to_srgb8, write_png
    from ...lt_addon.io.label import labelled_grid

    rows = rows[:max_rows]
    truths = np.concatenate([r["images"]["same_light"].ravel() for r in rows])
    exposure = 1.0 / max(float(np.percentile(truths, 99)), 1e-12)
    grid = []
    for r in rows:
        im, e = r["images"], r["errors"]
        line = [(im["relit"], f"steered az {r['azimuth']:.0f} el {r['elevation']:.0f}"),
                (im["same_light"], "Cycles, same light"),
                (4.0 * np.abs(im["relit"] - im["same_light"]),
                 f"|diff| x4 rel {e['same_light']['rel_fro']:.3f}")]
        if "sun" in im:
            line.append((im["sun"], f"Cycles Sun rel {e['sun']['rel_fro']:.3f}"))
        # bake images come bottom row first; PNG rows go top first
        grid.append([(linear_to_srgb8(img[::-1], exposure), text) for img, text in line])
    nbytes = write_png(path, labelled_grid(grid))
    return {"path": path, "bytes": nbytes, "exposure": exposure,
            "columns": ["steered", "cycles_same_light", "abs_difference_x4", "cycles_sun"]}
