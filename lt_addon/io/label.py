"""Text labels burnt into 8-bit images: captions for comparison pictures (NumPy only).

A built-in 5x7 bitmap font (plus 2 descender rows) covers ASCII letters, digits and common
punctuation, so the product can label its comparison PNGs without Pillow or matplotlib (Blender
ships neither). Images are (H, W, 3) uint8 with row 0 at the top (PNG order).
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

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


def caption(image8: np.ndarray, text: str, scale: int = 2, band=(40, 40, 40),
            ink=(255, 255, 255)) -> np.ndarray:
    """``image8`` (H, W, 3) uint8 with a band of height ``(9 + 4) * scale`` on top holding
    ``text`` (cut to the width, ending in "..." when cut); returns a new array."""
    img = np.asarray(image8, dtype=np.uint8)
    h, w = img.shape[:2]
    pad = 2 * scale
    fits = max((w - 2 * pad) // (ADVANCE * scale), 0)
    if len(text) > fits:
        text = text[:max(fits - 3, 0)] + "..." if fits >= 3 else text[:fits]
    strip = np.empty(((GLYPH_H + 4) * scale, w, 3), dtype=np.uint8)
    strip[:] = band
    mask = text_mask(text, scale)
    strip[pad:pad + mask.shape[0], pad:pad + mask.shape[1]][mask] = ink
    return np.concatenate([strip, img], axis=0)


def labelled_row(panels, gap: int = 4, scale: int = 2) -> np.ndarray:
    """Panels ``[(image8, text), ...]`` of one height, each captioned, side by side with
    ``gap`` black columns between them; (H + band, sum W + gaps, 3) uint8."""
    out = []
    for i, (img, text) in enumerate(panels):
        if i:
            out.append(np.zeros(((GLYPH_H + 4) * scale + np.shape(img)[0], gap, 3), np.uint8))
        out.append(caption(img, text, scale))
    heights = {p.shape[0] for p in out}
    if len(heights) != 1:
        raise ValueError(f"panels must share one height, got {sorted(heights)}")
    return np.concatenate(out, axis=1)


def labelled_grid(rows, gap: int = 4, min_width: int = 256, scale: int = 2) -> np.ndarray:
    """Rows of panels ``[[(image8, text), ...], ...]`` (all panels one shape, top row first)
    as one captioned grid: each panel enlarged by a whole factor (nearest texel) to at least
    ``min_width`` px wide so its caption reads, rows separated by ``gap`` black rows.

    Returns
    -------
    ndarray, uint8, shape (rows * (k H + band) + gaps, cols * k W + gaps, 3)
    """
    if not rows or not rows[0]:
        raise ValueError("nothing to lay out")
    w = np.shape(rows[0][0][0])[1]
    k = max(1, -(-int(min_width) // max(w, 1)))
    lines = [labelled_row([(np.asarray(img, np.uint8).repeat(k, 0).repeat(k, 1), text)
                           for img, text in row], gap=gap, scale=scale) for row in rows]
    width = max(line.shape[1] for line in lines)
    out = []
    for i, line in enumerate(lines):
        if i:
            out.append(np.zeros((gap, width, 3), np.uint8))
        pad = np.zeros((line.shape[0], width - line.shape[1], 3), np.uint8)
        out.append(np.concatenate([line, pad], axis=1))
    return np.concatenate(out, axis=0)
