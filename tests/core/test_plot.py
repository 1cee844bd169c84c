"""Dependency-free raster charts: pixel mapping, ticks, markers, font and PNG output."""

import numpy as np
import pytest

from relightable_textures.lt_addon.contact_sheet import read_png
from relightable_textures.lt_addon.plot import (
    PALETTE, Series, _ticks, format_tick, glyph, render_chart, text_mask, write_chart)

RED, GREEN, BLUE, WHITE = (255, 0, 0), (0, 200, 0), (0, 0, 255), (255, 255, 255)


def _count(img, color, r, c, half=7):
    """Pixels of exactly ``color`` in the (2*half+1)-square window centred on (r, c)."""
    win = img[max(r - half, 0):r + half + 1, max(c - half, 0):c + half + 1]
    return int(np.all(win == color, axis=-1).sum())


def test_single_point_lands_on_its_pixel_and_nothing_else_is_coloured():
    img, ax = render_chart([Series([2.0], [3.0], "", color=RED, line=False)], return_axes=True)
    assert img.shape == (420, 640, 3) and img.dtype == np.uint8
    r, c = ax.to_pixel(2.0, 3.0)
    assert tuple(img[r, c]) == RED
    # a single point sits in the middle of the padded range
    assert abs(c - (ax.left + ax.right) / 2) <= 1 and abs(r - (ax.top + ax.bottom) / 2) <= 1
    red = np.argwhere(np.all(img == RED, axis=-1))
    assert len(red) == 21  # the 5x5 disc marker, nothing else (no label -> no legend)
    assert np.abs(red - [r, c]).max() == 2
    assert tuple(img[r + 7, c + 23]) == WHITE and tuple(img[5, 5]) == WHITE


def test_pixel_mapping_of_the_axis_limits_and_frame():
    img, ax = render_chart([Series([0, 10], [0, 100], "", line=False)], return_axes=True,
                           width=500, height=300)
    assert img.shape == (300, 500, 3)
    r0, c0 = ax.to_pixel(0, 0)
    r1, c1 = ax.to_pixel(10, 100)
    # 5% padding on each side of the data range
    assert abs((c0 - ax.left) / (ax.right - ax.left) - 0.05 / 1.1) < 0.01
    assert abs((ax.bottom - r0) / (ax.bottom - ax.top) - 0.05 / 1.1) < 0.01
    assert r1 < r0 and c1 > c0  # row 0 at the top
    assert tuple(img[ax.top, (ax.left + ax.right) // 2]) == (0, 0, 0)  # frame
    with pytest.raises(ValueError):
        ax.to_pixel(np.nan, 1.0)


def test_log_axis_maps_decades_to_equal_spacing():
    img, ax = render_chart([Series([1, 10, 100], [1, 10, 100], "", color=RED)], logx=True,
                           logy=True, return_axes=True)
    (ra, ca), (rb, cb), (rc, cc) = (ax.to_pixel(v, v) for v in (1, 10, 100))
    assert abs((cb - ca) - (cc - cb)) <= 1 and cb - ca > 100
    assert abs((ra - rb) - (rb - rc)) <= 1 and ra - rb > 50
    for r, c in ((ra, ca), (rb, cb), (rc, cc)):
        assert tuple(img[r, c]) == RED
    with pytest.raises(ValueError):
        ax.to_pixel(-1.0, 10.0)  # non-positive on a log axis is not drawable


def test_line_between_points_is_drawn_and_broken_at_nan():
    img, ax = render_chart([Series([0, 10], [0, 10], "", color=BLUE, marker="none")],
                           return_axes=True)
    r0, c0 = ax.to_pixel(0, 0)
    r1, c1 = ax.to_pixel(10, 10)
    rm, cm = ax.to_pixel(5, 5)
    assert abs(rm - (r0 + r1) / 2) <= 1 and abs(cm - (c0 + c1) / 2) <= 1
    assert tuple(img[rm, cm]) == BLUE
    # every column between the end points holds line pixels
    assert all(np.all(img[:, c] == BLUE, axis=-1).any() for c in range(c0, c1 + 1))

    img, ax = render_chart([Series([0, 1, 2, 3], [0, 1, np.nan, 1], "", color=BLUE,
                                   marker="none")], return_axes=True)
    assert tuple(img[ax.to_pixel(0.5, 0.5)]) == BLUE
    r, c = ax.to_pixel(2, 1)  # would lie on a 1 -> 3 segment: the nan breaks the line
    assert _count(img, BLUE, r, c, half=3) == 0


def test_highlighted_points_are_bigger_and_ringed():
    img, ax = render_chart([Series([1, 3], [1, 1], "", color=GREEN, line=False,
                                   highlight=[True, False])], return_axes=True)
    (rh, ch), (rp, cp) = ax.to_pixel(1, 1), ax.to_pixel(3, 1)
    big, plain = _count(img, GREEN, rh, ch), _count(img, GREEN, rp, cp)
    assert (big, plain) == (37, 21)
    assert _count(img, (0, 0, 0), rh, ch) > 20 and _count(img, (0, 0, 0), rp, cp) == 0


def test_cross_marker_and_default_palette():
    img, ax = render_chart([Series([0, 1], [0, 1], "a", line=False),
                            Series([0, 1], [1, 0], "b", line=False, marker="x")],
                           return_axes=True)
    r, c = ax.to_pixel(0, 0)
    assert tuple(img[r, c]) == PALETTE[0] and _count(img, PALETTE[0], r, c, 4) == 21
    r, c = ax.to_pixel(1, 0)
    assert tuple(img[r, c]) == PALETTE[1] and _count(img, PALETTE[1], r, c, 4) == 13
    assert np.array_equal(img, render_chart([Series([0, 1], [0, 1], "a", line=False),
                                             Series([0, 1], [1, 0], "b", line=False,
                                                    marker="x")]))  # deterministic


def test_legend_lists_series_and_avoids_the_data():
    # data only in the top-right corner -> the legend goes elsewhere
    img, ax = render_chart([Series([9, 10], [9, 10], "corner data", color=RED)],
                           return_axes=True)
    frame = np.argwhere(np.all(img == (90, 90, 90), axis=-1))  # legend frame colour
    assert len(frame) > 50
    mid_r, mid_c = (ax.top + ax.bottom) / 2, (ax.left + ax.right) / 2
    assert not np.any((frame[:, 0] < mid_r) & (frame[:, 1] > mid_c))
    # its swatch repeats the series colour outside the data's neighbourhood
    red = np.argwhere(np.all(img == RED, axis=-1))
    assert np.any(red[:, 1] < mid_c)


def test_vline_is_dashed_at_its_x():
    img, ax = render_chart([Series([0, 10], [0, 1], "s")], vlines=[(4.0, "p*")],
                           annotations=[(10, 1, "end")], return_axes=True)
    c = ax.to_pixel(4.0, 0.5)[1]
    column = np.all(img[ax.top + 1:ax.bottom, c] == (90, 90, 90), axis=-1)
    assert 0.3 < column.mean() < 0.7  # dashed: about half the pixels on


def test_text_mask_glyph_counts_and_unknown_box():
    a = text_mask("A")
    assert a.shape == (9, 5) and a.sum() == 18 == glyph("A").sum()
    assert text_mask("AB").shape == (9, 11) and text_mask("").shape == (9, 0)
    big = text_mask("A", scale=2)
    assert big.shape == (18, 10) and big.sum() == 4 * 18
    box = text_mask("€")
    assert box.sum() == 20 and box[0].all() and box[6].all() and not box[7:].any()
    assert np.array_equal(text_mask("x€y")[:, 6:11], box)
    render_chart([], title="€uro \t ünïcode", xlabel="€")  # no exception


def test_font_covers_required_characters_with_distinct_glyphs():
    required = ("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789"
                " .,-+_/()%=:*<>[]'^")
    box = glyph("€")
    bitmaps = {}
    for ch in required:
        g = glyph(ch)
        assert g.shape == (9, 5)
        assert not np.array_equal(g, box), f"{ch!r} missing from the font"
        bitmaps.setdefault(g.tobytes(), []).append(ch)
    assert all(len(v) == 1 for v in bitmaps.values()), [v for v in bitmaps.values() if len(v) > 1]
    assert glyph(" ").sum() == 0 and glyph("g")[7:].any()  # descender rows are used


@pytest.mark.parametrize("v, step, text", [
    (1e-3, 1e-3, "1e-3"), (0.01, 0.01, "0.01"), (10.0, 10.0, "10"), (1e4, 1e4, "1e4"),
    (0.30000000000000004, 0.1, "0.3"), (25000.0, 5000.0, "2.5e4"), (20000.0, 5000.0, "2e4"),
    (0.0, 0.1, "0"), (1e-17, 0.1, "0"), (-0.5, 0.5, "-0.5"), (1500.0, 500.0, "1500"),
    (0.25, 0.05, "0.25"), (2e-3, 2e-3, "2e-3")])
def test_format_tick(v, step, text):
    assert format_tick(v, step) == text


def test_ticks_are_nice_and_inside_the_range():
    labels = [t for _, t in _ticks(0.0, 1.0, False)]
    assert labels == ["0", "0.2", "0.4", "0.6", "0.8", "1.0"]
    assert [t for _, t in _ticks(-0.05, 3.2, False)] == ["0", "1", "2", "3"]
    assert [t for _, t in _ticks(-1.3e4, 4.2e4, False)] == ["-1e4", "0", "1e4", "2e4", "3e4", "4e4"]
    assert [t for _, t in _ticks(-3.2, 4.1, True)] == ["0.01", "1", "100", "1e4"]
    assert [t for _, t in _ticks(-0.1, 2.1, True)] == ["1", "10", "100"]
    assert [t for _, t in _ticks(-2.3, -0.3, True)] == ["0.01", "0.02", "0.05", "0.1", "0.2", "0.5"]
    rng = np.random.default_rng(1)
    for _ in range(500):
        lo, span = rng.uniform(-1e3, 1e3), 10 ** rng.uniform(-5, 5)
        ticks = _ticks(lo, lo + span, False)
        pos = np.array([p for p, _ in ticks])
        assert 3 <= len(ticks) <= 7
        assert pos.min() >= lo - 1e-9 * span and pos.max() <= lo + span + 1e-9 * span
        step = (pos[-1] - pos[0]) / (len(pos) - 1)
        mant = step / 10 ** np.floor(np.log10(step))
        assert np.allclose(np.diff(pos), step, rtol=1e-6)
        assert min(abs(mant - m) for m in (1, 2, 5, 10)) < 1e-6  # 1-2-5 steps
        assert len({t for _, t in ticks}) == len(ticks)  # labels tell ticks apart


@pytest.mark.parametrize("series, kw", [
    ([], {}),
    ([], {"logx": True, "logy": True}),
    ([Series([np.nan, np.nan], [np.nan, 1.0], "all nan")], {}),
    ([Series([], [], "empty")], {"logy": True}),
    ([Series([2.0, 2.0, 2.0], [1.0, 2.0, 3.0], "constant x")], {}),
    ([Series([0.0, 0.0], [0.0, 0.0], "zeros")], {}),
    ([Series([-1.0, 0.0, 1.0, 10.0], [0.0, -5.0, 1.0, 2.0], "nonpositive")],
     {"logx": True, "logy": True}),
    ([Series([-1.0, 0.0], [-2.0, 0.0], "no positive")], {"logx": True, "logy": True}),
    ([Series([1.0, np.inf, 3.0], [1.0, 2.0, -np.inf], "inf", highlight=[True, True, True])], {}),
    ([Series([1.0], [1e-12], "tiny"), Series([1.0], [1e12], "huge")], {"logy": True}),
    ([Series([0, 1], [0, 1], "x")], {"vlines": [(np.nan, "nan"), (-1.0, "neg")],
                                      "annotations": [(np.nan, 1.0, "bad")], "logx": True}),
    ([Series([0, 1], [0, 1], "small")], {"width": 160, "height": 120, "title": "a long title"}),
])
def test_degenerate_input_renders(series, kw):
    img = render_chart(series, **kw)
    assert img.shape == (kw.get("height", 420), kw.get("width", 640), 3) and img.dtype == np.uint8
    assert (img == 0).any()  # at least the frame is drawn


def test_invalid_series_are_rejected():
    with pytest.raises(ValueError):
        Series([1, 2], [1], "mismatch")
    with pytest.raises(ValueError):
        Series([1, 2], [1, 2], "marker", marker="*")
    with pytest.raises(ValueError):
        Series([1, 2], [1, 2], "hl", highlight=[True])
    with pytest.raises(ValueError):
        render_chart([], width=30, height=30)


def test_write_chart_round_trips_through_png(tmp_path):
    series = [Series([1, 10, 100], [3, 2, 1], "s", highlight=[False, True, False])]
    kw = dict(title="Round trip", xlabel="x", ylabel="y", logx=True, vlines=[(10, "p*")])
    path = tmp_path / "chart.png"
    n = write_chart(path, series, **kw)
    assert n == path.stat().st_size > 0
    assert np.array_equal(read_png(str(path)), render_chart(series, **kw))


def test_tick_labels_are_thinned_on_small_charts():
    img, ax = render_chart([Series([0, 1], [0, 1], "")], width=160, height=120, return_axes=True)
    band = img[ax.bottom + 6:ax.bottom + 6 + 9]  # the x tick label row
    cols = np.flatnonzero(np.any(np.all(band == 0, axis=-1), axis=0))
    gaps = np.diff(cols)
    labels = 1 + np.sum(gaps > 5)  # ink inside a label is at most 4 blank columns apart
    assert labels == 3  # 0, 0.4, 0.8 (0.2 and 0.6 dropped)
    assert gaps[gaps > 5].min() >= 7  # >= 6 blank columns between neighbouring labels
    wide = render_chart([Series([0, 1], [0, 1], "")], width=640)
    assert wide.shape == (420, 640, 3)
