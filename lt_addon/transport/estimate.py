"""What a transport-texture bake will cost, predicted before it starts (issue 33).

A bake's stages scale with what they work on:

=================  ==========================================  ===============================
stage              scales with                                 measured as
=================  ==========================================  ===============================
``direct``         texels x objects (albedo, then T's rays     ``seconds["direct_total"]``
                   or Cycles calls)                            minus the horizons'
``horizons``       horizon texels x objects (the horizon map's ``seconds["horizons"]``
                   scan by rays, at its own side)
``indirect``       indirect texels (``indirect_resolution``)   ``seconds["indirect_total"]``
                   (Cycles' steerable bakes, or the gather's   minus the gather's PCA
                   points and rays; calibrated at the bake's
                   own grid, up to 256^2)
``indirect_pca``   texels x objects (the gathered term's PCA   ``seconds["indirect_pca"]``
                   reads T's rows; its bounce operator, the
                   rays' hits, is fixed by the grid)
``fit``            texels x objects (the PCA over T, the       ``seconds["fit"]`` minus the
                   viewport's checks)                          block viewport's
``fit_choose``     objects (the block viewport's choice fits   ``seconds["fit_choose"]``
                   sampled regions of at most 64^2 texels:
                   units ``min(side, 128)^2``)
``fit_blocks``     texels x objects (the block viewport's fit  ``seconds["fit_blocks"]``
                   and its check, once chosen)
``other``          texels x objects (store, stacking, ...)     ``bake_total`` minus the above
``truth``          texels x objects x lights                   the truth bakes' seconds
=================  ==========================================  ===============================

:func:`fit_costs` takes the stage seconds of two calibration bakes of the same scene and settings
at small sizes (the bpy layer runs them: ``operators/bakes/estimate.py``) and fits each stage as
``a + b x size``. Doing this on the machine and scene at hand measures everything the figures
depend on: cores, Cycles' speed, the scene's triangles, the sample counts. :func:`predict`
applies the fit to the asked size. Disk, RAM and GPU memory come from the bake's own formulas
(the transport store's bytes, the fit's working set, the viewport's atlas).

Units: seconds, bytes. Sizes are texel counts.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

# the share of an object's horizons the trial on sampled tiles finds first (one tile in 8)
from .horizon_trial import FRACTION as TRIAL_SHARE

STAGES = ("direct", "horizons", "indirect", "indirect_pca", "fit", "fit_choose", "fit_blocks",
          "other",
          "truth")
#: The stages of the bake itself (the truths come after it).
BAKE_STAGES = STAGES[:-1]


@dataclass
class StageCost:
    """``seconds = fixed + per_unit * units`` of one stage."""

    fixed: float
    per_unit: float

    def at(self, units: float) -> float:
        return max(0.0, self.fixed + self.per_unit * units)


def stage_seconds(seconds: dict) -> dict:
    """The stage split of a bake's ``seconds`` (its report's timings):
    {direct, horizons, indirect, indirect_pca, fit, other} in seconds, non-negative."""
    direct = float(seconds.get("direct_total", 0.0))
    horizons = min(float(seconds.get("horizons", 0.0)), direct)
    indirect = float(seconds.get("indirect_total", 0.0))
    pca = min(float(seconds.get("indirect_pca", 0.0)), indirect)
    fit = float(seconds.get("fit", 0.0))
    choose = min(float(seconds.get("fit_choose", 0.0)), fit)
    blocks = min(float(seconds.get("fit_blocks", 0.0)), fit - choose)
    total = float(seconds.get("bake_total", direct + indirect + fit))
    return {"direct": direct - horizons, "horizons": horizons, "indirect": indirect - pca,
            "indirect_pca": pca, "fit": fit - choose - blocks, "fit_choose": choose,
            "fit_blocks": blocks,
            "other": max(0.0, total - direct - indirect - fit)}


def units(stage: str, resolution: int, indirect_resolution: int, n_objects: int,
          truth_lights: int, horizon_resolution: int | None = None) -> float:
    """What ``stage`` scales with at these settings (texels; see the module table;
    ``horizon_resolution`` the horizon map's side, the texture's when None)."""
    P = float(resolution) ** 2 * n_objects
    if stage == "indirect":
        return float(indirect_resolution) ** 2 * n_objects
    if stage == "horizons":
        side = resolution if horizon_resolution is None else horizon_resolution
        return float(side) ** 2 * n_objects
    if stage == "truth":
        return P * truth_lights
    if stage == "fit_choose":
        return float(min(int(resolution), 128)) ** 2 * n_objects
    return P


def fit_costs(samples: list) -> dict:
    """Per stage, the line through the calibration points ``samples``: a list of
    ``(units_by_stage, seconds_by_stage)``, one per calibration bake, at two or more sizes.
    A per-unit cost the noise made negative is 0 (the stage is then its measured fixed cost,
    the larger calibration's seconds); a negative fixed cost makes the stage proportional to
    its size through the larger calibration. Points all at one size (the indirect term, calibrated
    at the bake's own grid) give a stage proportional to its size through their mean: exact at
    that size, scaled with the size beyond it."""
    out = {}
    for stage in STAGES:
        pts = [(u[stage], s[stage]) for u, s in samples if stage in u and stage in s]
        if not pts:
            continue
        if len(pts) == 1 or max(p[0] for p in pts) == min(p[0] for p in pts):
            mean = sum(p[1] for p in pts) / len(pts)
            out[stage] = (StageCost(0.0, mean / pts[0][0]) if pts[0][0] > 0 else
                          StageCost(mean, 0.0))
            continue
        n = len(pts)
        mx = sum(p[0] for p in pts) / n
        my = sum(p[1] for p in pts) / n
        sxx = sum((p[0] - mx) ** 2 for p in pts)
        b = sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx
        if b <= 0:
            out[stage] = StageCost(max(p[1] for p in pts), 0.0)
        elif my - b * mx < 0:      # through 0 and the largest calibration, the nearest one
            x, y = max(pts)
            out[stage] = StageCost(0.0, y / x)
        else:
            out[stage] = StageCost(my - b * mx, b)
    return out


def predict(costs: dict, resolution: int, indirect_resolution: int, n_objects: int,
            truth_lights: int, horizon_resolution: int | None = None) -> dict:
    """{stage: seconds, "bake": the bake's seconds (direct + horizons + indirect + fit +
    other), "total": with the truths} at the asked settings."""
    out = {}
    for stage, cost in costs.items():
        if stage == "truth" and not truth_lights:
            continue
        if stage in ("indirect", "indirect_pca") and not indirect_resolution:
            continue
        out[stage] = cost.at(units(stage, resolution, indirect_resolution, n_objects,
                                   truth_lights, horizon_resolution))
    out["bake"] = sum(out.get(s, 0.0) for s in BAKE_STAGES)
    out["total"] = out["bake"] + out.get("truth", 0.0)
    return out


def readable_seconds(seconds: float) -> str:
    """``42 s`` / ``3.5 min`` / ``1.2 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def _fraction(message: str, prefix: str) -> float | None:
    """``i / n`` of a progress message ``"<prefix> i/n ..."``, or None."""
    if not message.startswith(prefix):
        return None
    try:
        i, n = message[len(prefix):].split()[0].split("/")
        return min(max(int(i) / max(int(n), 1), 0.0), 1.0)
    except (ValueError, IndexError):
        return None


def estimated_elapsed(seconds: dict, message: str) -> float | None:
    """Seconds the estimate ``seconds`` ({stage: s}) expects a bake to have taken when it
    prints ``message`` (its direction, horizon, horizon-trial, indirect and fit steps), None
    for other steps.
    "other" (albedo, writing) is counted before the directions."""
    other, direct = seconds.get("other", 0.0), seconds.get("direct", 0.0)
    horizons = seconds.get("horizons", 0.0)
    indirect = seconds.get("indirect", 0.0) + seconds.get("indirect_pca", 0.0)
    fit = sum(seconds.get(s, 0.0) for s in ("fit", "fit_choose", "fit_blocks"))
    f = _fraction(message, "direction ")
    if f is not None:
        return other + direct * f
    for prefix, share in (("horizons ", 1.0), ("horizon trial ", TRIAL_SHARE)):
        f = _fraction(message, prefix)
        if f is None:
            continue
        # "horizons k/A azimuths, object i/n": objects in turn; the trial on sampled tiles
        # (horizon_trial) finds about an eighth of an object's horizons first
        f *= share
        obj = re.search(r"object (\d+)/(\d+)", message)
        if obj is not None:
            i, n = int(obj[1]), max(int(obj[2]), 1)
            f = (i - 1 + f) / n
        return other + direct + horizons * f
    f = _fraction(message, "indirect bake ")
    if f is not None:
        return other + direct + horizons + indirect * f
    if message.startswith("indirect light: "):   # the gathered term: points and rays, its PCA
        pca = seconds.get("indirect_pca", 0.0)
        done = indirect - pca if "PCA" in message else 0.0
        return other + direct + horizons + done
    if message.startswith("indirect light gathered"):
        return other + direct + horizons + indirect
    if message.startswith("models fitted"):
        return other + direct + horizons + indirect + fit
    return None


def time_left(seconds: dict, message: str, elapsed: float, last: float | None = None) -> float:
    """The bake's time left when it prints ``message`` after ``elapsed`` seconds: the estimate's
    remaining stages scaled by how fast the bake has gone so far against the estimate
    (measured / estimated elapsed, once a tenth of the estimate is behind), so a machine
    slower or faster than the calibration moves the figure at once. ``last``: the previous
    figure, kept for steps the estimate does not place."""
    total = sum(seconds.get(s, 0.0) for s in BAKE_STAGES)
    at = estimated_elapsed(seconds, message)
    if at is None:
        return max(0.0, total - elapsed) if last is None else last
    ratio = elapsed / at if at >= 0.1 * total and at > 0 else 1.0
    return max(0.0, (total - at) * ratio)
