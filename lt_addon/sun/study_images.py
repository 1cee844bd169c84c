"""Pictures of a sun study (bpy-free, NumPy only): the sunlight-hours map in a false-colour
ramp with its legend, and the shadow-study sheet of relit textures with captions.

Images are (H, W, 3) uint8, row 0 at the top (PNG order); the textures they are made from
have row 0 at v = 0 (the bake's order) and are flipped here. Captions use the built-in bitmap
font of :mod:`..io.label` (no Pillow: Blender ships none).
"""

from __future__ import annotations

import numpy as np

from ..io.contact_sheet import linear_to_srgb8
from ..io.label import GLYPH_H, caption, text_mask

__all__ = ["RAMP", "UNCOVERED", "ramp", "hours_picture", "sheet"]

#: The false-colour ramp: matplotlib's *viridis* at 9 stops (dark blue 0, yellow at the top),
#: perceptually even and readable in grey and by the colour-blind.
RAMP = np.array([(68, 1, 84), (71, 44, 122), (59, 81, 139), (44, 113, 142), (33, 144, 141),
                 (39, 173, 129), (92, 200, 99), (170, 220, 50), (253, 231, 37)], np.float64)
#: Texels the bake did not fill (outside the UV islands).
UNCOVERED = (56, 56, 56)
_BG = (24, 24, 24)
_INK = (235, 235, 235)


def ramp(x) -> np.ndarray:
    """``x`` in [0, 1] (any shape; clipped) to RGB uint8 (..., 3) through :data:`RAMP`."""
    t = np.clip(np.asarray(x, np.float64), 0.0, 1.0) * (len(RAMP) - 1)
    i = np.minimum(np.floor(t).astype(np.int64), len(RAMP) - 2)
    f = (t - i)[..., None]
    return np.rint(RAMP[i] * (1 - f) + RAMP[i + 1] * f).astype(np.uint8)


def _upscale(img, min_width: int) -> np.ndarray:
    k = max(1, -(-int(min_width) // max(img.shape[1], 1)))
    return img.repeat(k, axis=0).repeat(k, axis=1)


def _text(canvas, text: str, y: int, x: int, scale: int = 1, ink=_INK) -> None:
    """Burn ``text`` into ``canvas`` at (y, x) (top left), cut at the canvas' edge."""
    m = text_mask(text, scale)
    h = min(m.shape[0], canvas.shape[0] - y)
    w = min(m.shape[1], canvas.shape[1] - x)
    if h > 0 and w > 0:
        canvas[y:y + h, x:x + w][m[:h, :w]] = ink


def _nice_ticks(top: float) -> list:
    """About five round tick values from 0 to ``top``."""
    if top <= 0:
        return [0.0]
    raw = top / 4.0
    mag = 10.0 ** np.floor(np.log10(raw))
    step = min((s * mag for s in (1, 2, 2.5, 5, 10) if s * mag >= raw), default=10 * mag)
    ticks = list(np.arange(0.0, top + 1e-9, step))
    return [float(t) for t in ticks]


def _titled(img, title, scale: int):
    """``img`` under ``title``: a line, or lines (a list) each in its own band."""
    for line in reversed([title] if isinstance(title, str) else list(title)):
        if line:
            img = caption(img, line, scale)
    return img


def hours_picture(hours, covered, top_h: float, title="", *,
                  min_width: int = 640, scale: int = 2, legend: str | None = None) -> np.ndarray:
    """The sunlight-hours map ``hours`` (R, R) (row 0 at v = 0) in :data:`RAMP` from 0 to
    ``top_h`` hours (the study's possible hours: maps of one study share a scale), texels not
    ``covered`` in :data:`UNCOVERED`, enlarged (nearest texel) to at least ``min_width`` px,
    with ``title`` (a line or a list of lines) above and a legend strip below: the ramp, ticks
    in hours (or ``legend``'s unit), and what it shows (``legend``: that line, for another
    quantity on the same ramp)."""
    what = legend                    # the legend's line of text (default: hours)
    h = np.asarray(hours, np.float64)
    cov = np.asarray(covered, bool)
    img = ramp(h / top_h if top_h > 0 else np.zeros_like(h))
    img[~cov] = UNCOVERED
    img = _upscale(img[::-1], min_width)
    W = img.shape[1]
    pad = 4 * scale
    line = (GLYPH_H + 3) * scale
    # the legend: a bar, its ticks and their labels, then a line of text
    bar_h = 8 * scale
    legend = np.zeros((pad + bar_h + 3 * scale + 3 * line + pad, W, 3), np.uint8)
    legend[:] = _BG
    x0, x1 = pad, W - pad
    xs = np.linspace(0.0, 1.0, max(x1 - x0, 2))
    legend[pad:pad + bar_h, x0:x0 + len(xs)] = ramp(xs)[None, :, :]
    y_tick = pad + bar_h
    for t in _nice_ticks(top_h):
        x = x0 + int(round(t / top_h * (len(xs) - 1))) if top_h > 0 else x0
        legend[y_tick:y_tick + 3 * scale, max(x - scale // 2, 0):x + max(scale // 2, 1)] = _INK
        label = f"{t:g}"
        w = (6 * len(label) - 1) * scale
        _text(legend, label, y_tick + 3 * scale + scale, int(np.clip(x - w // 2, 0, W - w)),
              scale)
    _text(legend, what or f"hours of direct sun, of {top_h:g} h",
          y_tick + 3 * scale + line + scale, x0, scale)
    _text(legend, "dark grey: no texel", y_tick + 3 * scale + 2 * line + scale, x0, scale)
    return _titled(np.concatenate([img, legend], axis=0), title, scale)


def sheet(cells, n_cols: int, title="", *, min_width: int = 256, gap: int = 4,
          scale: int = 2) -> np.ndarray:
    """A shadow-study sheet: ``cells`` a row-major list of ``(image, line1, line2)`` --
    ``image`` (H, W) linear grey or (H, W, 3) linear RGB, display range [0, 1], row 0 at the
    bottom (v = 0 of a texture, the first row of a render), or None (a blank cell: a clock
    time the day does not have) -- laid out ``n_cols`` a row, each enlarged to at least
    ``min_width`` px and captioned with two lines, under ``title`` (a line or lines)."""
    if not cells:
        raise ValueError("a sheet needs at least one cell")
    shape = next((np.shape(c[0])[:2] for c in cells if c[0] is not None), (32, 32))
    tiles = []
    for img, line1, line2 in cells:
        if img is None:
            rgb = np.zeros(tuple(shape) + (3,), np.uint8)
            rgb[:] = _BG
        else:
            g = linear_to_srgb8(np.asarray(img, np.float64))
            rgb = g if g.ndim == 3 else np.repeat(g[..., None], 3, axis=2)
        tile = _upscale(rgb[::-1], min_width)
        tiles.append(caption(caption(tile, line2, scale), line1, scale))
    th, tw = tiles[0].shape[:2]
    n_rows = -(-len(tiles) // n_cols)
    out = np.zeros((n_rows * th + (n_rows - 1) * gap, n_cols * tw + (n_cols - 1) * gap, 3),
                   np.uint8)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, n_cols)
        out[r * (th + gap):r * (th + gap) + th, c * (tw + gap):c * (tw + gap) + tw] = tile
    return _titled(out, title, scale)
