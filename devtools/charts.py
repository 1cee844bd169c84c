"""Line / scatter charts of benchmark and analysis results, drawn with matplotlib (development only).

Blender does not ship matplotlib and the extension needs no chart at run time, so charts live
here, outside the extension zip: ``make bench`` and ``relight analyze`` from a source checkout
draw them (matplotlib is in requirements.txt; the installed extension writes the JSON and CSV
only). One call, :func:`write_chart`, takes :class:`Series` in data units.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np

MARKERS = ("o", "x", "none")


@dataclass
class Series:
    """One data series: ``x``, ``y`` (n,) in data units, drawn as a line and/or markers.

    ``marker``: "o", "x" or "none"; ``highlight`` (n,) bool rings points (e.g. Pareto-optimal);
    ``color`` an RGB triple of 0..255 ints or None for the palette colour.
    """
    x: np.ndarray
    y: np.ndarray
    label: str = ""
    color: tuple | None = None
    line: bool = True
    marker: str = "o"
    highlight: np.ndarray | None = None

    def __post_init__(self):
        self.x = np.asarray(self.x, dtype=np.float64).reshape(-1)
        self.y = np.asarray(self.y, dtype=np.float64).reshape(-1)
        if self.x.shape != self.y.shape:
            raise ValueError(f"x and y differ in length: {self.x.size} vs {self.y.size}")
        if self.highlight is not None:
            self.highlight = np.asarray(self.highlight, dtype=bool).reshape(-1)
            if self.highlight.shape != self.x.shape:
                raise ValueError("highlight must have one flag per point")
        if self.marker not in MARKERS:
            raise ValueError(f"marker must be one of {MARKERS}, got {self.marker!r}")
        if self.color is not None:
            self.color = tuple(int(c) for c in self.color)
            if len(self.color) != 3 or not all(0 <= c <= 255 for c in self.color):
                raise ValueError(f"color must be 3 ints in 0..255, got {self.color}")


def write_chart(path: str, series: Sequence[Series] = (), *, title: str = "", xlabel: str = "",
                ylabel: str = "", logx: bool = False, logy: bool = False, width: int = 640,
                height: int = 420, vlines: Sequence[tuple[float, str]] = ()) -> int:
    """Draw the series into a ``width`` x ``height`` pixel PNG at ``path`` (written to a
    temporary name, then renamed); returns its size in bytes.

    Points that are not finite (or not positive on a log axis) are left out and break lines.
    ``vlines``: (x, label) dashed vertical markers, e.g. an optimum.
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from ..lt_addon.io.atomic import atomic_path

    dpi = 100
    fig, ax = plt.subplots(figsize=(width / dpi, height / dpi), dpi=dpi)
    try:
        for i, s in enumerate(series):
            x, y = s.x.copy(), s.y.copy()
            bad = ~(np.isfinite(x) & np.isfinite(y))
            if logx:
                bad |= ~(x > 0)
            if logy:
                bad |= ~(y > 0)
            x[bad], y[bad] = np.nan, np.nan
            color = (tuple(c / 255 for c in s.color) if s.color is not None else f"C{i % 10}")
            ax.plot(x, y, linestyle="-" if s.line else "none",
                    marker=None if s.marker == "none" else s.marker, markersize=4,
                    color=color, label=s.label or None)
            if s.highlight is not None and s.highlight.any():
                ax.plot(x[s.highlight], y[s.highlight], linestyle="none", marker="o",
                        markersize=10, markerfacecolor="none", markeredgecolor=color)
        for x, label in vlines:
            ax.axvline(x, linestyle="--", color="0.4", linewidth=1)
            ax.annotate(label, (x, 1), xycoords=("data", "axes fraction"), rotation=90,
                        va="top", ha="right", fontsize=8, color="0.3")
        if logx:
            ax.set_xscale("log")
        if logy:
            ax.set_yscale("log")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.grid(True, which="major", color="0.9")
        if any(s.label for s in series):
            ax.legend(fontsize=8, loc="best")
        fig.tight_layout()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=dpi)
    finally:
        plt.close(fig)
    return os.path.getsize(path)


def available() -> bool:
    """True when matplotlib can be imported (a source checkout's venv)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


# --- the two charts of `relight analyze` (Mahajan et al. 2007's analysis on real transport) ---
def dimensionality_chart(report: dict) -> list:
    """Chart series: one log-log dimensionality curve per seed vertex."""
    dim = report["dimensionality"]
    out = []
    for c in dim["curves"]:
        label = f"vertex {c['seed']}: slope {c['slope']:.2f}"
        out.append(Series(np.array(c["sizes"], float), np.array(c["dims"], float), label))
    return out


def cost_chart(report: dict) -> tuple[list, list]:
    """Chart series and vertical markers: measured cost per vertex vs cluster count."""
    curve = report["cost_curve"]
    k = np.array([r["clusters"] for r in curve], float)
    c = np.array([r["cost_per_vertex"] for r in curve], float)
    best = k == report["optimum"]["clusters"]
    series = [Series(k, c, "fixed CPCA (measured)", highlight=best),
              Series(np.array([report["adaptive"]["clusters"]], float),
                          np.array([report["adaptive"]["cost_per_vertex"]], float),
                          "adaptive (paper: from 8, halving)", line=False, marker="x"),
              Series(np.array([report["auto"]["clusters"]], float),
                          np.array([report["auto"]["cost_per_vertex"]], float),
                          "auto (from predicted, halving/quartering)", line=False, marker="x")]
    marks = [(float(report["optimum"]["clusters"]), "optimum")]
    if report["predicted_clusters"]:
        marks.append((float(report["predicted_clusters"]), "predicted V/p*"))
    return series, marks


def analysis_charts(report: dict, out_dir: str, stem: str) -> dict:
    """Draw ``<stem>_dimensionality.png`` (patch dimensionality vs patch size, log-log, one
    curve per seed vertex, fitted slope in the legend) and ``<stem>_cost.png`` (cost per vertex
    vs cluster count, log x: the measured optimum, the count predicted from the slope
    ``V / p*`` and the two adaptive results marked); returns their paths."""
    paths = {"dimensionality_png": os.path.join(out_dir, f"{stem}_dimensionality.png"),
             "cost_png": os.path.join(out_dir, f"{stem}_cost.png")}
    dim = report["dimensionality"]
    write_chart(paths["dimensionality_png"], dimensionality_chart(report),
                title=f"{report['object']}: patch dimensionality (99.95% energy), mean "
                      f"slope {dim['slope']:.2f}",
                xlabel="patch size (vertices)", ylabel="dimensionality", logx=True, logy=True)
    series, marks = cost_chart(report)
    write_chart(paths["cost_png"], series,
                title=f"{report['object']}: CPCA cost, N = {report['N']}, tol {report['tol']:g}",
                xlabel="clusters", ylabel="multiply-adds per vertex", logx=True, vlines=marks)
    return paths


def analysis_charts_plugin(report: dict, out_dir: str, stem: str) -> dict:
    """The ``analysis-charts`` plugin (:mod:`..lt_addon.plugins`): :func:`analysis_charts`
    where matplotlib is installed, else nothing."""
    return analysis_charts(report, out_dir, stem) if available() else {}
