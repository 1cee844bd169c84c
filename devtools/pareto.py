"""Pareto fronts of benchmark sweeps, preset choice, atomic CSV output and error metrics.

A benchmark sweeps bake settings (basis order, samples, resolution, storage precision, ...)
and records one *point* per setting: a dict of numeric metrics such as ``bake_seconds``,
``stored_bytes``, ``preview_madds`` (multiply-adds per texel/vertex per update), ``rel_rmse``
(error against a Cycles reference), ``psnr_db`` and ``max_abs_error``.

* :func:`pareto_mask` / :func:`pareto_mask_nd` -- which points are not dominated
  (all objectives are "lower is better").
* :func:`choose_presets` -- pick named presets (draft / balanced / production) from the
  measured Pareto front only, with a human-readable ``"why"`` per choice.
* :func:`write_csv` / :func:`read_csv` -- atomic CSV of the points.
* :func:`error_metrics` -- relative RMSE, PSNR and max abs error of an estimate vs a reference.

Pure NumPy + standard library; no Blender imports.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..lt_addon.io import atomic

__all__ = [
    "pareto_mask",
    "pareto_mask_nd",
    "choose_presets",
    "write_csv",
    "read_csv",
    "error_metrics",
]


# --------------------------------------------------------------------------- Pareto masks


def pareto_mask_nd(matrix) -> np.ndarray:
    """Non-dominated rows of an ``(n, m)`` objective matrix (every column: lower is better).

    Parameters
    ----------
    matrix : array_like, shape (n, m)
        Row ``i`` holds the ``m`` objective values of point ``i``. Converted to float64.

    Returns
    -------
    numpy.ndarray of bool, shape (n,)
        ``True`` for rows that no other row dominates. Row ``j`` dominates row ``i`` when
        ``matrix[j] <= matrix[i]`` in every column and ``<`` in at least one.

    Rules: identical rows do not dominate each other, so ties are all kept. A row containing
    NaN is never optimal and never dominates another row. ``+inf``/``-inf`` compare as usual.
    Cost is O(n^2 m) time and O(n m) memory, fine for n in the low thousands.
    """
    a = np.asarray(matrix, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError(f"matrix must have shape (n, m), got shape {a.shape}")
    n, m = a.shape
    if m == 0:
        raise ValueError("matrix needs at least one objective column (m >= 1)")
    valid = ~np.isnan(a).any(axis=1)
    mask = valid.copy()
    b = a[valid]  # only valid rows may dominate
    for i in np.flatnonzero(valid):
        le = (b <= a[i]).all(axis=1)
        lt = (b < a[i]).any(axis=1)
        if np.any(le & lt):
            mask[i] = False
    return mask


def pareto_mask(costs, errors) -> np.ndarray:
    """Non-dominated points of a two-objective sweep (lower cost and lower error are better).

    Parameters
    ----------
    costs : array_like, shape (n,)
        Cost per point (e.g. seconds, bytes, multiply-adds).
    errors : array_like, shape (n,)
        Error per point (e.g. relative RMSE).

    Returns
    -------
    numpy.ndarray of bool, shape (n,)
        ``True`` where no other point has ``cost <=`` and ``error <=`` with at least one strict.
        Identical points are all kept; a point with NaN cost or error is never optimal and never
        dominates. Same rules as :func:`pareto_mask_nd` with ``m = 2``.
    """
    c = np.asarray(costs, dtype=np.float64)
    e = np.asarray(errors, dtype=np.float64)
    if c.ndim != 1 or e.ndim != 1 or c.shape != e.shape:
        raise ValueError(
            f"costs and errors must both have shape (n,), got {c.shape} and {e.shape}"
        )
    return pareto_mask_nd(np.stack([c, e], axis=1))


# --------------------------------------------------------------------------- presets

#: Built-in rule names accepted in ``choose_presets(rules=...)``.
RULES = ("cheapest", "knee", "lowest_error")


def _as_float(value: Any, key: str, index: int) -> float:
    if value is None:
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(
            f"point {index}: value of {key!r} is not numeric: {value!r}"
        ) from None


def _num(v: float) -> str:
    """Compact figure: integers-ish and large values without decimals, else 3 significant."""
    if not math.isfinite(v):
        return repr(v)
    if abs(v) >= 1000 or (v == int(v) and abs(v) >= 1):
        return f"{v:.0f}"
    return f"{v:.3g}"


def _cost_text(key: str, v: float) -> str:
    if key.endswith("_seconds") or key == "seconds":
        return f"{_num(v)} s"
    if key.endswith("_bytes") or key == "bytes":
        return f"{_num(v)} bytes"
    return f"{key} {_num(v)}"


def _axis01(v: np.ndarray) -> tuple[np.ndarray, str]:
    """Scale to [0, 1] over the front: log10 if all values are > 0, else linear."""
    if np.all(v > 0):
        t, scale = np.log10(v), "log"
    else:
        t, scale = v.copy(), "linear"
    lo, hi = float(t.min()), float(t.max())
    if hi > lo:
        return (t - lo) / (hi - lo), scale
    return np.zeros_like(t), scale


def choose_presets(
    points: Sequence[Mapping[str, Any]],
    cost_key: str = "bake_seconds",
    error_key: str = "rel_rmse",
    names: Sequence[str] = ("draft", "balanced", "production"),
    rules: Mapping[str, str | Callable[[np.ndarray, np.ndarray], int]] | None = None,
) -> dict[str, dict]:
    """Choose named presets from the measured Pareto front of ``(points[cost_key], points[error_key])``.

    Only points with finite cost and error are considered; the Pareto front
    (:func:`pareto_mask`, both lower is better) is taken over those, identical front points
    are merged (the first one in ``points`` order represents them), and the distinct front
    points are sorted by increasing cost (hence decreasing error). A dominated point is never
    chosen.

    Default rule (``rules=None``; ``names`` must then have 3 entries, mapped in order):

    * ``names[0]`` (draft) -- ``"cheapest"``: the front point with the lowest cost.
    * ``names[2]`` (production) -- ``"lowest_error"``: the front point with the lowest error.
    * ``names[1]`` (balanced) -- ``"knee"``: the front point closest (Euclidean) to the utopia
      point ``(0, 0)`` after mapping log10(cost) and log10(error) each linearly to [0, 1] over
      the front (an axis with a value <= 0 is scaled linearly instead of in log). Ties go to
      the cheaper point. The two end points of the front always lie at distance exactly 1, so
      the knee is an end point only if no interior point is closer; then, if at least 3
      distinct front points exist, the neighbouring front point toward the middle is taken
      instead (index 1 after the cheapest, or the one before the lowest-error point).

    With fewer than 3 distinct front points some names share a point; their ``"why"`` says so.

    Parameters
    ----------
    points : sequence of dict
        One dict per measured setting; every dict must contain ``cost_key`` and ``error_key``
        (``None`` counts as NaN, i.e. not usable).
    cost_key, error_key : str
        Keys of the two objectives, both lower is better.
    names : sequence of 3 str
        Names for the default rules (cheapest, knee, lowest_error). Ignored when ``rules`` given.
    rules : mapping name -> rule, optional
        Custom presets, in output order. A rule is one of ``"cheapest"``, ``"knee"``,
        ``"lowest_error"``, or a callable ``f(costs, errors) -> int`` receiving the distinct front
        sorted by increasing cost (two float64 arrays of shape (k,)) and returning an index into
        it (so it cannot choose a dominated point). ``"knee"`` is moved off an end point as above.

    Returns
    -------
    dict name -> dict
        A shallow copy of the chosen point dict with an added ``"why"`` string stating the rule
        and figures, e.g. ``"lowest error on the Pareto front: rel_rmse 0.074 at 1508 s ..."``.
        (An existing ``"why"`` key in the point is overwritten.)

    Raises
    ------
    ValueError
        No points, a point missing ``cost_key``/``error_key``, a non-numeric value, no point
        with finite cost and error, bad ``names``/``rules``, or a callable returning a bad index.
    """
    points = list(points)
    if not points:
        raise ValueError("choose_presets: no points given")
    for i, p in enumerate(points):
        missing = [k for k in (cost_key, error_key) if k not in p]
        if missing:
            raise ValueError(
                f"choose_presets: point {i} is missing key(s) {missing}; "
                f"available keys: {sorted(map(str, p.keys()))}"
            )
    cost = np.array([_as_float(p[cost_key], cost_key, i) for i, p in enumerate(points)])
    err = np.array([_as_float(p[error_key], error_key, i) for i, p in enumerate(points)])
    finite = np.isfinite(cost) & np.isfinite(err)
    if not finite.any():
        raise ValueError(
            f"choose_presets: no point has a finite {cost_key!r} and {error_key!r} "
            f"({len(points)} point(s) given)"
        )

    if rules is None:
        names = list(names)
        if len(names) != 3 or len(set(names)) != 3:
            raise ValueError(
                f"choose_presets: names must be 3 distinct names when rules is None, got {names}"
            )
        rules = {names[0]: "cheapest", names[1]: "knee", names[2]: "lowest_error"}
    else:
        rules = dict(rules)
        if not rules:
            raise ValueError("choose_presets: rules is empty")
        for name, rule in rules.items():
            if not callable(rule) and rule not in RULES:
                raise ValueError(
                    f"choose_presets: rule for {name!r} must be one of {RULES} or a callable, "
                    f"got {rule!r}"
                )

    # Pareto front over the finite points, duplicates merged, sorted by cost.
    idx = np.flatnonzero(finite)
    on_front = pareto_mask(cost[idx], err[idx])
    seen: dict[tuple[float, float], int] = {}
    for j in idx[on_front]:
        seen.setdefault((float(cost[j]), float(err[j])), int(j))
    front = sorted(seen.values(), key=lambda j: (cost[j], err[j], j))
    fc, fe = cost[front], err[front]
    k = len(front)
    n_dominated = int(finite.sum()) - int(on_front.sum())
    context = (
        f"Pareto front of {k} distinct point(s) over {cost_key} vs {error_key}; "
        f"{n_dominated} dominated and {int((~finite).sum())} non-finite point(s) excluded"
    )

    def figures(pos: int) -> str:
        return f"{error_key} {_num(float(fe[pos]))} at {_cost_text(cost_key, float(fc[pos]))}"

    chosen: dict[str, int] = {}
    whys: dict[str, str] = {}
    for name, rule in rules.items():
        if callable(rule):
            pos = rule(fc.copy(), fe.copy())
            if isinstance(pos, (bool, np.bool_)) or not isinstance(pos, (int, np.integer)):
                raise ValueError(
                    f"choose_presets: rule for {name!r} must return an int index, got {pos!r}"
                )
            pos = int(pos)
            if not 0 <= pos < k:
                raise ValueError(
                    f"choose_presets: rule for {name!r} returned index {pos}, front has {k} points"
                )
            why = f"custom rule {getattr(rule, '__name__', 'callable')} on the Pareto front: {figures(pos)}"
        elif rule == "cheapest":
            pos = 0
            why = f"cheapest point on the Pareto front: {figures(pos)}"
        elif rule == "lowest_error":
            pos = k - 1
            why = f"lowest error on the Pareto front: {figures(pos)}"
        else:  # knee
            x, xs = _axis01(fc)
            y, ys = _axis01(fe)
            dist = np.hypot(x, y)
            pos = int(np.argmin(dist))  # first minimum = cheaper on ties
            why = (
                f"knee of the Pareto front (closest to the utopia point in normalised "
                f"{xs} {cost_key} / {ys} {error_key} space, distance {dist[pos]:.3f}): "
                f"{figures(pos)}"
            )
            if k >= 3 and pos in (0, k - 1):
                end = "cheapest" if pos == 0 else "lowest-error"
                pos = 1 if pos == 0 else k - 2
                why = (
                    f"knee of the Pareto front: the closest point to the utopia point "
                    f"(normalised {xs} {cost_key} / {ys} {error_key}) was the {end} end point, "
                    f"so the next front point toward the middle was taken (distance "
                    f"{dist[pos]:.3f}): {figures(pos)}"
                )
        chosen[name] = pos
        whys[name] = why

    out: dict[str, dict] = {}
    for name, pos in chosen.items():
        why = f"{whys[name]} ({context})"
        others = [o for o, q in chosen.items() if q == pos and o != name]
        if others:
            why += (
                f"; shares this point with {', '.join(others)} because the Pareto front has "
                f"only {k} distinct point(s)" if k < 3 else
                f"; shares this point with {', '.join(others)}"
            )
        d = dict(points[front[pos]])
        d["why"] = why
        out[name] = d
    return out


# --------------------------------------------------------------------------- CSV


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, (set, frozenset)):
        return sorted(o, key=repr)
    raise TypeError(f"cannot JSON-encode {type(o).__name__}: {o!r}")


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))  # shortest string that round-trips the float64
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (dict, list, tuple, np.ndarray, set, frozenset)):
        return json.dumps(v, default=_json_default)
    return str(v)


def write_csv(path: str | os.PathLike, rows: Sequence[Mapping[str, Any]]) -> int:
    """Write ``rows`` to ``path`` as UTF-8 CSV, atomically; return the number of bytes written.

    The header is the union of the rows' keys in first-seen order; a row lacking a key gets an
    empty cell, as does ``None``. Floats (incl. NumPy floats, via float64) are written with
    ``repr`` precision so they read back bit-exact; dict/list/tuple/ndarray values are
    JSON-encoded. Lines end with ``"\\n"``. No rows -> an empty file (0 bytes).

    The file is written to a temporary name in the same folder, flushed and fsynced, then moved
    over ``path`` with :func:`os.replace`; on any error the temporary file is removed and an
    existing ``path`` is left untouched.
    """
    path = os.fspath(path)
    rows = list(rows)
    header: dict[str, None] = {}
    for r in rows:
        for key in r:
            header.setdefault(str(key), None)
    buf = io.StringIO()
    if rows:
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(list(header))
        for r in rows:
            rs = {str(k): v for k, v in r.items()}
            w.writerow([_cell(rs.get(k)) for k in header])
    data = buf.getvalue().encode("utf-8")

    return atomic.write_bytes(path, data)


def read_csv(path: str | os.PathLike) -> list[dict[str, str]]:
    """Read a CSV written by :func:`write_csv`: one ``dict[str, str]`` per data row (no parsing)."""
    with open(path, newline="", encoding="utf-8") as f:
        return [dict(r) for r in csv.DictReader(f)]


# --------------------------------------------------------------------------- error metrics


def error_metrics(estimate, reference, peak: float | None = None) -> dict[str, float]:
    """Error of ``estimate`` against ``reference`` (same shape, any shape), in float64.

    Returns a dict of Python floats:

    ``rel_rmse``
        ``||estimate - reference||_F / ||reference||_F`` -- dimensionless ratio (not percent).
        0 when both are all zero; ``inf`` when the reference is all zero and the estimate is not.
    ``rmse``, ``mse``
        Root-mean-square / mean-square difference over all elements, in the inputs' units
        (squared units for ``mse``).
    ``psnr_db``
        ``10 * log10(peak**2 / mse)`` in decibels; ``inf`` when the arrays are identical
        (``mse == 0``), ``-inf`` when ``peak == 0`` and ``mse > 0``.
    ``max_abs_error``
        ``max |estimate - reference|``, in the inputs' units (e.g. linear radiance).
    ``peak``
        The peak used: ``max(reference)`` when ``peak`` is None, else the value given.

    Raises ValueError if the shapes differ or the arrays are empty.
    """
    e = np.asarray(estimate, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    if e.shape != r.shape:
        raise ValueError(f"estimate shape {e.shape} != reference shape {r.shape}")
    if e.size == 0:
        raise ValueError("error_metrics: empty arrays")
    d = (e - r).ravel()
    diff_norm = float(np.linalg.norm(d))
    ref_norm = float(np.linalg.norm(r.ravel()))
    if ref_norm == 0.0:
        rel = 0.0 if diff_norm == 0.0 else math.inf
    else:
        rel = diff_norm / ref_norm
    mse = float(np.mean(d * d))
    pk = float(np.max(r)) if peak is None else float(peak)
    if mse == 0.0:
        psnr = math.inf
    elif pk == 0.0:
        psnr = -math.inf
    else:
        psnr = 10.0 * math.log10(pk * pk / mse)
    return {
        "rel_rmse": rel,
        "rmse": math.sqrt(mse),
        "mse": mse,
        "psnr_db": psnr,
        "max_abs_error": float(np.max(np.abs(d))),
        "peak": pk,
    }
