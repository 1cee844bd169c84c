"""Tiny dependency-free raster charts (line / scatter plots) written as 8-bit RGB PNGs.

Only NumPy: text is drawn with a built-in 5x7 bitmap font (plus 2 descender rows), so charts can
be written from the CLI, benchmarks and tests without matplotlib or Pillow.

Conventions: images are (H, W, 3) uint8 with row 0 at the top (PNG order); pixel positions are
(row, col). Non-finite points, and non-positive values on log axes, are skipped, never fatal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Sequence

import numpy as np

from .contact_sheet import read_png, write_png

__all__ = ["Series", "Axes", "render_chart", "write_chart", "text_mask", "glyph", "format_tick",
           "PALETTE", "read_png"]

RGB = tuple[int, int, int]
WHITE: RGB = (255, 255, 255)
INK: RGB = (0, 0, 0)
GRID: RGB = (225, 225, 225)
MUTED: RGB = (90, 90, 90)
# Okabe-Ito colour-blind-safe palette, ordered for contrast on white (yellow last).
PALETTE: tuple[RGB, ...] = ((0, 114, 178), (213, 94, 0), (0, 158, 115), (204, 121, 167),
                            (230, 159, 0), (86, 180, 233), (0, 0, 0), (240, 228, 66))
MARKERS = ("o", "x", "none")

# --- bitmap font ------------------------------------------------------------------------------
# Each glyph: the character, then 9 base-32 digits, one per row (top first; 7 body rows + 2
# descender rows), each digit a 5-bit row with the most significant bit the leftmost column.
GLYPH_H, GLYPH_W, ADVANCE = 9, 5, 6
_B32 = "0123456789ABCDEFGHIJKLMNOPQRSTUV"
_FONT_DATA = (
    "AEHHHVHH00BUHHUHHU00CEHGGGHE00DSIHHHIS00EVGGUGGV00FVGGUGGG00GEHGNHHF00HHHHVHHH00"
    "IE44444E00J72222IC00KHIKOKIH00LGGGGGGV00MHRLLHHH00NHHPLJHH00OEHHHHHE00PUHHUGGG00"
    "QEHHHLID00RUHHUKIH00SFGGE11U00TV44444400UHHHHHHE00VHHHHHA400WHHHLLLA00XHHA4AHH00"
    "YHHA444400ZV1248GV000EHJLPHE0014C4444E002EH1248V003V2421HE00426AIV22005VGU11HE00"
    "668GUHHE007V124888008EHHEHHE009EHHF12C00a00E1FHF00bGGUHHHU00c00EGGHE00d11FHHHF00"
    "e00EHVGE00f698S88800g00FHHHF1EhGGMPHHH00i40C444E00j2062222ICkGGIKOKI00lC44444300"
    "m00QLLLL00n00MPHHH00o00EHHHE00p00UHHHUGGq00FHHHF11r00MPGGG00s00FGE1U00t88S889600"
    "u00HHHJD00v00HHHA400w00HHLLA00x00HA4AH00y00HHHHF1Ez00V248V00 000000000.00000CC00"
    ",00000CC48-000V00000+044V44000_0000000V0/11248GG00(248884200)842224800%OP248J300"
    "=00V0V0000:0CC0CC000;0CC0CC480*04LEL4000<248G84200>842124800[E88888E00]E22222E00"
    "'448000000^4AH000000!444440400?EH1240400\"AAA000000#AAVAVAA00|444444400~008L20000"
    "&CIK8LID00$4FKE5U400@EH1DLLE00"
)


def _decode_font(data: str) -> MappingProxyType:
    glyphs = {}
    for i in range(0, len(data), 1 + GLYPH_H):
        rows = np.array([_B32.index(d) for d in data[i + 1:i + 1 + GLYPH_H]])
        bits = ((rows[:, None] >> np.arange(GLYPH_W - 1, -1, -1)) & 1).astype(bool)
        bits.setflags(write=False)
        glyphs[data[i]] = bits
    return MappingProxyType(glyphs)


_GLYPHS = _decode_font(_FONT_DATA)
_BOX = np.zeros((GLYPH_H, GLYPH_W), dtype=bool)  # unknown characters: a 5x7 outline box
_BOX[[0, 6], :] = True
_BOX[:7, [0, -1]] = True
_BOX.setflags(write=False)


def glyph(ch: str) -> np.ndarray:
    """(9, 5) bool bitmap of one character (rows 0-6 body, 7-8 descender); unknown -> box."""
    return _GLYPHS.get(ch, _BOX)


def text_mask(text: str, scale: int = 1) -> np.ndarray:
    """Bool bitmap of ``text``: shape (9 * scale, (6 * len(text) - 1) * scale), 1 px letter gap."""
    m = np.zeros((GLYPH_H, max(ADVANCE * len(text) - 1, 0)), dtype=bool)
    for i, ch in enumerate(text):
        m[:, ADVANCE * i:ADVANCE * i + GLYPH_W] = glyph(ch)
    return m.repeat(scale, axis=0).repeat(scale, axis=1)


def format_tick(v: float, step: float) -> str:
    """Compact tick label for value ``v`` on a grid of spacing ``step``: '0.01', '250', '1e-3', '2.5e4'."""
    if v == 0 or abs(v) < abs(step) * 1e-6:
        return "0"
    mag = math.floor(math.log10(abs(v)) + 1e-9)
    smag = math.floor(math.log10(abs(step)) + 1e-9)
    if -2 <= mag < 4:
        return f"{v:.{max(0, -smag)}f}"
    mant, exp = f"{v:.{max(0, mag - smag)}e}".split("e")
    if "." in mant:
        mant = mant.rstrip("0").rstrip(".")
    return f"{mant}e{int(exp)}"


# --- data model -------------------------------------------------------------------------------
@dataclass
class Series:
    """One data series: ``x``, ``y`` (n,) in data units; drawn as a line and/or markers.

    marker: "o" (filled dot, 5 px), "x" (cross, 7 px) or "none". ``highlight`` (n,) bool marks
    points drawn as bigger ringed dots (e.g. Pareto-optimal). ``color`` None -> palette colour.
    """
    x: np.ndarray
    y: np.ndarray
    label: str = ""
    color: RGB | None = None
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


def _to_axis(v, log: bool) -> np.ndarray:
    """Data -> axis space (log10 on log axes); nan where not finite or (log) not positive."""
    v = np.asarray(v, dtype=np.float64)
    if log:
        v = np.where(v > 0, np.log10(np.where(v > 0, v, 1.0)), np.nan)
    return np.where(np.isfinite(v), v, np.nan)


@dataclass(frozen=True)
class Axes:
    """Pixel geometry of a rendered chart: frame at rows ``top``/``bottom``, cols ``left``/``right``.

    ``xlim``/``ylim`` are the axis limits in axis space (log10 of the data on log axes).
    """
    left: int
    right: int
    top: int
    bottom: int
    xlim: tuple[float, float]
    ylim: tuple[float, float]
    logx: bool = False
    logy: bool = False

    def col_of(self, tx):
        """Float column of axis-space x (log10 of the data on a log axis)."""
        return self.left + (tx - self.xlim[0]) / (self.xlim[1] - self.xlim[0]) * (self.right - self.left)

    def row_of(self, ty):
        """Float row of axis-space y (log10 of the data on a log axis)."""
        return self.bottom - (ty - self.ylim[0]) / (self.ylim[1] - self.ylim[0]) * (self.bottom - self.top)

    def project(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Float pixel positions (rows, cols) of data points; nan where a point is not drawable."""
        row, col = self.row_of(_to_axis(y, self.logy)), self.col_of(_to_axis(x, self.logx))
        bad = ~(np.isfinite(row) & np.isfinite(col))
        return np.where(bad, np.nan, row), np.where(bad, np.nan, col)

    def to_pixel(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the pixel where data point (x, y) is drawn; ValueError if not drawable."""
        row, col = self.project(x, y)
        if not (np.isfinite(row) and np.isfinite(col)):
            raise ValueError(f"point ({x}, {y}) cannot be drawn on these axes")
        return int(np.rint(row)), int(np.rint(col))


def _axis_range(values: np.ndarray, log: bool) -> tuple[float, float]:
    """Axis-space limits covering ``values`` with 5% padding; padded sensibly if empty/constant."""
    v = _to_axis(values, log)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    if hi - lo <= 1e-9 * max(abs(lo), abs(hi), 1e-300):
        pad = 1.0 if log else (0.1 * abs(lo) or 1.0)
        return lo - pad, hi + pad
    return lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)


def _linear_ticks(lo: float, hi: float, target: int = 5) -> tuple[list[float], float]:
    """1-2-5 ticks inside [lo, hi] (as close to ``target`` ticks as possible) and their step."""
    base = 10.0 ** math.floor(math.log10((hi - lo) / target))
    best = None
    for step in (base, 2 * base, 5 * base, 10 * base):
        k0, k1 = math.ceil(lo / step - 1e-9), math.floor(hi / step + 1e-9)
        score = abs(k1 - k0 + 1 - target)
        if best is None or score < best[0]:  # ties: the denser grid
            best = (score, step, k0, k1)
    _, step, k0, k1 = best
    return [k * step for k in range(k0, k1 + 1)], step


def _ticks(lo: float, hi: float, log: bool) -> list[tuple[float, str]]:
    """(axis-space position, label) ticks: 1-2-5 steps on linear axes, decades on log axes."""
    if not log:
        values, step = _linear_ticks(lo, hi)
        return [(v, format_tick(v, step)) for v in values]
    d0, d1 = math.ceil(lo - 1e-9), math.floor(hi + 1e-9)
    decades = [(float(k), format_tick(10.0 ** k, 10.0 ** k)) for k in range(d0, d1 + 1)
               if k % max(1, math.ceil((d1 - d0 + 1) / 6)) == 0]  # <= 6 ticks
    if len(decades) >= 3:
        return decades
    mant = [(math.log10(m) + k, m * 10.0 ** k) for k in range(d0 - 1, d1 + 1) for m in (1, 2, 5)]
    mant = [(p, format_tick(v, v)) for p, v in mant if lo - 1e-9 <= p <= hi + 1e-9]
    if len(mant) > 8 and len(decades) >= 2:
        return decades
    if len(mant) >= 3:
        return mant
    values, step = _linear_ticks(10.0 ** lo, 10.0 ** hi)
    return [(math.log10(v), format_tick(v, step)) for v in values if v > 0]


def _thin(ticks, pixel, need):
    """Every k-th tick, k as small as keeps neighbours ``need(label_a, label_b)`` px apart."""
    for k in range(1, len(ticks) + 1):
        kept = ticks[::k]
        if all(abs(pixel(b[0]) - pixel(a[0])) >= need(a[1], b[1]) for a, b in zip(kept, kept[1:])):
            return kept
    return ticks[:1]


# --- raster primitives ------------------------------------------------------------------------
def _paint(img, rows, cols, color, clip=None) -> None:
    """Set pixels (rows, cols) to ``color``, skipping any outside ``clip`` (r0, r1, c0, c1) / image."""
    r0, r1, c0, c1 = clip or (0, img.shape[0] - 1, 0, img.shape[1] - 1)
    rows, cols = np.asarray(rows, dtype=int), np.asarray(cols, dtype=int)
    ok = (rows >= max(r0, 0)) & (rows <= min(r1, img.shape[0] - 1))
    ok &= (cols >= max(c0, 0)) & (cols <= min(c1, img.shape[1] - 1))
    img[rows[ok], cols[ok]] = color


def _blit(img, mask, row, col, color, clip=None) -> None:
    """Paint the True pixels of ``mask`` with its top-left corner at (row, col)."""
    rr, cc = np.nonzero(mask)
    _paint(img, rr + row, cc + col, color, clip)


def _fill(img, r0, r1, c0, c1, color) -> None:
    """Fill the inclusive rectangle rows r0..r1, cols c0..c1, clipped to the image."""
    r0, c0 = max(r0, 0), max(c0, 0)
    img[r0:max(r1 + 1, r0), c0:max(c1 + 1, c0)] = color


def _frame(img, r0, r1, c0, c1, color) -> None:
    for rect in ((r0, r0, c0, c1), (r1, r1, c0, c1), (r0, r1, c0, c0), (r0, r1, c1, c1)):
        _fill(img, *rect, color)


def _segment(img, r0, c0, r1, c1, color, clip=None, width=2, dash=0) -> None:
    """Line from (r0, c0) to (r1, c1) (float pixels) by dense sampling; ``dash`` px on/off."""
    n = int(min(max(abs(r1 - r0), abs(c1 - c0)), 4 * sum(img.shape[:2]))) + 1
    t = np.linspace(0.0, 1.0, n)
    rows, cols = np.rint(r0 + t * (r1 - r0)).astype(int), np.rint(c0 + t * (c1 - c0)).astype(int)
    if dash:
        on = (np.arange(n) // dash) % 2 == 0
        rows, cols = rows[on], cols[on]
    for dr in range(width):
        for dc in range(width):
            _paint(img, rows + dr, cols + dc, color, clip)


def _draw_text(img, text, row, col, color=INK, ha="left", va="top", scale=1, rotate=False):
    """Draw ``text`` anchored at (row, col); ha left/center/right, va top/center/bottom.

    ``rotate`` turns it 90 degrees counter-clockwise (reads bottom to top)."""
    m = text_mask(text, scale)
    if rotate:
        m = np.rot90(m)
    h, w = m.shape
    center_row = h // 2 if rotate else 3 * scale  # centre of the glyph body, not the descender
    col -= {"left": 0, "center": w // 2, "right": w}[ha]
    row -= {"top": 0, "center": center_row, "bottom": h}[va]
    _blit(img, m, row, col, color)


def _disc(radius: float, k: int | None = None) -> np.ndarray:
    """Bool disc of ``radius`` px in a (2k+1)-square stamp (k defaults to ceil(radius))."""
    k = int(math.ceil(radius)) if k is None else k
    d = np.arange(-k, k + 1)
    return d[:, None] ** 2 + d[None, :] ** 2 <= radius ** 2


_DOT = _disc(2.5)                                      # 5x5, 21 px
_BIG_DOT = _disc(3.6)                                  # 7x7, 37 px
_RING = _disc(5.6) & ~_disc(4.6, 6)
_d = np.arange(-3, 4)
_CROSS = np.abs(_d[:, None]) == np.abs(_d[None, :])  # 7x7, 13 px
_STAMPS = {"o": _DOT, "x": _CROSS, "none": np.zeros((1, 1), dtype=bool)}


def _stamp(img, mask, row, col, color, clip=None) -> None:
    """Paint ``mask`` centred on pixel (row, col)."""
    _blit(img, mask, int(row) - mask.shape[0] // 2, int(col) - mask.shape[1] // 2, color, clip)


# --- chart ------------------------------------------------------------------------------------
def _draw_series(img, ax: Axes, s: Series, color: RGB, clip) -> None:
    rows, cols = ax.project(s.x, s.y)
    ok = np.isfinite(rows)
    if s.line:
        for i in np.nonzero(ok[:-1] & ok[1:])[0]:
            _segment(img, rows[i], cols[i], rows[i + 1], cols[i + 1], color, clip)
    r, c = np.rint(rows[ok]).astype(int), np.rint(cols[ok]).astype(int)
    hl = s.highlight[ok] if s.highlight is not None else np.zeros(r.size, dtype=bool)
    for ri, ci, h in zip(r, c, hl):
        if h:
            _stamp(img, _RING, ri, ci, INK, clip)
            _stamp(img, _BIG_DOT, ri, ci, color, clip)
        else:
            _stamp(img, _STAMPS[s.marker], ri, ci, color, clip)


def _draw_legend(img, ax: Axes, entries: list[tuple[Series, RGB]]) -> None:
    """Legend box in the plot corner covering the fewest already-drawn data pixels."""
    row_h, swatch = 12, 18
    h = 6 + row_h * len(entries)
    w = 8 + swatch + 5 + max(len(s.label) for s, _ in entries) * ADVANCE
    r_lo, r_hi = ax.top + 6, ax.bottom - 6 - h
    c_lo, c_hi = ax.left + 6, ax.right - 6 - w
    corners = [(r_lo, c_hi), (r_lo, c_lo), (r_hi, c_hi), (r_hi, c_lo)]  # TR, TL, BR, BL

    def busy(r0, c0):
        region = img[max(r0, 0):r0 + h + 1, max(c0, 0):c0 + w + 1].astype(int)
        return int(np.sum(np.any(region != 255, -1) & np.any(region != GRID, -1)))

    r0, c0 = min(corners, key=lambda rc: busy(*rc))
    _fill(img, r0, r0 + h, c0, c0 + w, WHITE)
    _frame(img, r0, r0 + h, c0, c0 + w, MUTED)
    for i, (s, color) in enumerate(entries):
        mid = r0 + 4 + row_h * i + 5
        if s.line:
            _fill(img, mid, mid + 1, c0 + 4, c0 + 4 + swatch, color)
        _stamp(img, _STAMPS[s.marker if s.marker != "none" or s.line else "o"],
               mid, c0 + 4 + swatch // 2, color)
        _draw_text(img, s.label, mid, c0 + 9 + swatch, INK, va="center")


def render_chart(series: Sequence[Series] = (), *, title: str = "", xlabel: str = "",
                 ylabel: str = "", logx: bool = False, logy: bool = False, width: int = 640,
                 height: int = 420, vlines: Sequence[tuple[float, str]] = (),
                 annotations: Sequence[tuple[float, float, str]] = (), return_axes: bool = False):
    """Render a line/scatter chart; returns an (height, width, 3) uint8 image (and its Axes).

    vlines: (x, label) vertical dashed markers (e.g. an optimum); annotations: (x, y, text)
    placed next to a data point. Both are included in the axis ranges.
    """
    series = list(series)
    xs = [s.x for s in series] + [np.array([v for v, _ in vlines] + [a[0] for a in annotations])]
    ys = [s.y for s in series] + [np.array([a[1] for a in annotations], dtype=float)]
    xlim, ylim = _axis_range(np.concatenate(xs), logx), _axis_range(np.concatenate(ys), logy)
    xticks, yticks = _ticks(*xlim, logx), _ticks(*ylim, logy)

    title_scale = 2 if len(title) * ADVANCE * 2 <= width - 16 else 1
    top = 10 + (GLYPH_H * title_scale + 8 if title else 0)
    left = 8 + (GLYPH_H + 6 if ylabel else 0) + max([len(t) for _, t in yticks] + [1]) * ADVANCE + 6
    bottom = height - 1 - (8 + (GLYPH_H + 6 if xlabel else 0) + GLYPH_H + 6)
    right = width - 1 - max(10, (len(xticks[-1][1]) * ADVANCE // 2 + 4) if xticks else 0)
    if right - left < 20 or bottom - top < 20:
        raise ValueError(f"chart {width}x{height} too small for its labels")
    ax = Axes(left, right, top, bottom, xlim, ylim, logx, logy)
    clip = (top + 1, bottom - 1, left + 1, right - 1)
    img = np.full((height, width, 3), 255, dtype=np.uint8)
    xticks = _thin(xticks, ax.col_of, lambda a, b: (len(a) + len(b)) * ADVANCE / 2 + 6)
    yticks = _thin(yticks, ax.row_of, lambda a, b: GLYPH_H + 4)

    for pos, text in xticks:
        col = int(np.rint(ax.col_of(pos)))
        _fill(img, top + 1, bottom - 1, col, col, GRID)
        _fill(img, bottom + 1, bottom + 3, col, col, INK)
        _draw_text(img, text, bottom + 6, col, ha="center")
    for pos, text in yticks:
        row = int(np.rint(ax.row_of(pos)))
        _fill(img, row, row, left + 1, right - 1, GRID)
        _fill(img, row, row, left - 3, left - 1, INK)
        _draw_text(img, text, row, left - 6, ha="right", va="center")

    colors = [s.color or PALETTE[i % len(PALETTE)] for i, s in enumerate(series)]
    for s, color in zip(series, colors):
        _draw_series(img, ax, s, color, clip)
    for x, label in vlines:
        col = ax.col_of(_to_axis(x, logx))
        if np.isfinite(col):
            c = int(np.rint(col))
            _segment(img, top + 1, c, bottom - 1, c, MUTED, clip, width=1, dash=4)
            flip = c + 4 + len(label) * ADVANCE > right - 2
            _draw_text(img, label, top + 4, c - 4 if flip else c + 4, MUTED,
                       ha="right" if flip else "left")
    for x, y, text in annotations:
        r, c = ax.project(x, y)
        if np.isfinite(r):
            flip = c + 7 + len(text) * ADVANCE > right - 2
            r0 = int(r) - 14 if r - 14 > top + 2 else int(r) + 6  # above the point if room
            c0 = int(c) - 6 - len(text) * ADVANCE if flip else int(c) + 6
            _fill(img, r0 - 1, r0 + GLYPH_H - 1, c0 - 1, c0 + len(text) * ADVANCE - 1, WHITE)
            _draw_text(img, text, r0, c0, INK)
    _frame(img, top, bottom, left, right, INK)

    entries = [(s, c) for s, c in zip(series, colors) if s.label]
    if entries:
        _draw_legend(img, ax, entries)
    if title:
        _draw_text(img, title, 8, width // 2, ha="center", scale=title_scale)
    if xlabel:
        _draw_text(img, xlabel, height - 8, (left + right) // 2, ha="center", va="bottom")
    if ylabel:
        _draw_text(img, ylabel, (top + bottom) // 2, 8, va="center", rotate=True)
    return (img, ax) if return_axes else img


def write_chart(path, series: Sequence[Series] = (), **kw) -> int:
    """Render a chart (keyword arguments as :func:`render_chart`) and write it as PNG; returns bytes."""
    kw.pop("return_axes", None)
    return write_png(str(path), render_chart(series, **kw))
