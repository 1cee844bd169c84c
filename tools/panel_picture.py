"""A picture of the Relight panel, drawn from what the panel draws: docs/images/panel.png.

Blender's UI cannot be captured headless (no window, no GPU drawing), so this is not a
screenshot. The add-on is registered in bpy on Blender's factory startup scene (the default
cube selected and active, the file unsaved: what a newcomer sees first), and the panels'
``draw`` methods run against a recording layout (as tests/blender/test_panel.py does): every
row's labels, properties with their UI names and current values, and buttons, in drawing
order. Those rows are then drawn in Blender's default dark theme colours with the project's
own bitmap font and PNG writer (lt_addon/io/label.py, contact_sheet.py): no Pillow, no
matplotlib. The widget shapes only approximate Blender's; the words and values are the
panel's. The unsaved file's bake folder holds the time of the run, so the picture changes a
little each time it is made.

Usage (the development venv): ``.venv/bin/python tools/panel_picture.py [--out PNG]
[--rows]``; ``--rows`` prints the recorded rows too.
"""

from __future__ import annotations

import argparse
import os
import types

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: The panels drawn, in order: (class name, open?). The Bake sub-panel's Basic part is the
#: point; its Advanced sub-panel is closed by default and drawn as a closed header.
PANELS = (("VIEW3D_PT_relight", True), ("VIEW3D_PT_relight_bake", True),
          ("VIEW3D_PT_relight_bake_advanced", False))

#: Characters the bitmap font lacks, written out (the degree sign gets a glyph of its own).
ASCII = {"\u00b2": "^2", "\u00d7": "x", "\u2026": "...", "\u2014": "-", "\u2013": "-",
         "\u2019": "'", "\u201c": '"', "\u201d": '"'}
DEGREE = np.array([[0, 1, 1, 0, 0], [1, 0, 0, 1, 0], [1, 0, 0, 1, 0], [0, 1, 1, 0, 0]] +
                  [[0] * 5] * 5, dtype=bool)


class _Row:
    """One line of the panel: its items side by side."""

    def __init__(self, depth: int):
        self.items, self.depth = [], depth


class RecordingLayout:
    """Stands in for ``bpy.types.UILayout``: records what ``draw`` puts in it, as rows of
    items ``{"kind": "prop" | "op" | "label", ...}``. A ``row()`` puts its items side by
    side; a column or the layout itself gives each item its own row."""

    def __init__(self, rows: list, depth: int = 0, horizontal: bool = False, boxed=False):
        self.rows, self.depth, self.horizontal, self.boxed = rows, depth, horizontal, boxed
        self._row = None
        self.enabled = self.active = True
        self.alert = self.use_property_split = self.use_property_decorate = False
        self.scale_y = 1.0

    def _place(self, item: dict) -> None:
        item["boxed"] = self.boxed
        if self.horizontal:
            if self._row is None:
                self._row = _Row(self.depth)
                self.rows.append(self._row)
            self._row.items.append(item)
        else:
            row = _Row(self.depth)
            row.items.append(item)
            self.rows.append(row)

    def row(self, **k):
        return RecordingLayout(self.rows, self.depth, True, self.boxed)

    def column(self, **k):
        return RecordingLayout(self.rows, self.depth, False, self.boxed)

    split = column_flow = grid_flow = column

    def box(self, **k):
        return RecordingLayout(self.rows, self.depth, False, True)

    def prop(self, data, name, text=None, expand=False, placeholder=None, **k):
        import bpy

        rna = data.bl_rna.properties[name]
        value = getattr(data, name)
        if rna.type == "ENUM":
            shown = bpy.types.UILayout.enum_item_name(data, name, value) or str(value)
        elif rna.type == "FLOAT":
            shown = f"{value:.{max(rna.precision, 0)}f}"
        else:
            shown = value
        self._place({"kind": "prop", "name": name, "type": rna.type, "subtype": rna.subtype,
                     "label": rna.name if text is None else text, "value": shown,
                     "placeholder": placeholder or ""})

    def operator(self, idname, text=None, icon=None, **k):
        import bpy

        module, fn = idname.split(".")
        op = getattr(getattr(bpy.ops, module), fn)
        try:
            enabled = bool(op.poll())
        except Exception:   # a poll that needs a window's context: drawn enabled
            enabled = True
        self._place({"kind": "op", "name": idname, "icon": icon, "enabled": enabled,
                     "label": op.get_rna_type().name if text is None else text})
        return types.SimpleNamespace()

    def label(self, text="", icon=None, **k):
        self._place({"kind": "label", "label": text, "icon": icon})

    def separator(self, **k):
        pass


def fresh_scene():
    """Blender's factory startup scene, unsaved, the cube selected and active, with the
    extension registered; returns the context."""
    import bpy

    import relightable_textures

    bpy.ops.wm.read_homefile(use_empty=False, use_factory_startup=True)
    relightable_textures.register()
    cube = bpy.data.objects["Cube"]
    bpy.context.view_layer.objects.active = cube
    cube.select_set(True)
    return bpy.context


def record_panels(context) -> list:
    """``[(panel label, open?, depth, rows)]`` for :data:`PANELS`."""
    import bpy

    out = []
    for depth, (name, is_open) in enumerate(PANELS):
        cls = getattr(bpy.types, name)
        rows = []
        if is_open:
            cls.draw(types.SimpleNamespace(layout=RecordingLayout(rows)), context)
        out.append((cls.bl_label, is_open, depth, rows))
    return out


def describe(panels) -> str:
    """The recorded rows as text, one line a row."""
    lines = []
    for label, is_open, depth, rows in panels:
        lines.append("  " * depth + ("v " if is_open else "> ") + label)
        for row in rows:
            parts = []
            for it in row.items:
                if it["kind"] == "prop":
                    parts.append(f"[{it['label']}: {it['value'] or it['placeholder']!s}]"
                                 if it["type"] != "BOOLEAN"
                                 else f"[{'x' if it['value'] else ' '}] {it['label']}")
                elif it["kind"] == "op":
                    parts.append(f"<{it['label']}>" + ("" if it["enabled"] else " (greyed)"))
                else:
                    parts.append(it["label"])
            lines.append("  " * (depth + 1) + " | ".join(parts))
    return "\n".join(lines)


# -- drawing ---------------------------------------------------------------------------------

#: Blender's default theme, roughly (RGB 0-255).
BG, HEADER, SUBHEADER, TEXT, DIM = (48, 48, 48), (61, 61, 61), (55, 55, 55), (230, 230, 230), \
    (140, 140, 140)
FIELD, BUTTON, MENU, CHECK, BOX = (29, 29, 29), (84, 84, 84), (40, 40, 40), (84, 84, 84), \
    (42, 42, 42)
BORDER = (30, 30, 30)

SCALE = 2                 # font pixels per bitmap pixel
ROW_H = 13 * SCALE        # one row of widgets
PAD = 4 * SCALE


def _ascii(text: str) -> str:
    return "".join(ASCII.get(c, c if ord(c) < 128 or c == "\u00b0" else "?") for c in str(text))


def text_mask(text: str) -> np.ndarray:
    """The bitmap of ``text`` at :data:`SCALE` (lt_addon/io/label.py's font, plus a degree
    sign)."""
    from relightable_textures.lt_addon.io.label import ADVANCE, GLYPH_H, GLYPH_W, glyph

    m = np.zeros((GLYPH_H, max(ADVANCE * len(text) - 1, 0)), dtype=bool)
    for i, ch in enumerate(text):
        m[:, ADVANCE * i:ADVANCE * i + GLYPH_W] = DEGREE if ch == "\u00b0" else glyph(ch)
    return m.repeat(SCALE, axis=0).repeat(SCALE, axis=1)


class Canvas:
    def __init__(self, width: int, height: int):
        self.img = np.empty((height, width, 3), dtype=np.uint8)
        self.img[:] = BG

    def rect(self, x0, y0, x1, y1, colour, border=None):
        self.img[y0:y1, x0:x1] = colour
        if border is not None:
            self.img[y0, x0:x1] = self.img[y1 - 1, x0:x1] = border
            self.img[y0:y1, x0] = self.img[y0:y1, x1 - 1] = border

    def text(self, x, y_mid, text, colour=TEXT, max_w=None, centre_w=None, right=None):
        """``text`` from ``x`` (centred in ``centre_w``, or ending at ``right``), cut with
        "..." where it passes ``max_w``, as Blender cuts a label."""
        from relightable_textures.lt_addon.io.label import ADVANCE

        text = _ascii(text)
        if max_w is not None:
            fits = max(max_w // (ADVANCE * SCALE), 0)
            if len(text) > fits:
                text = text[:max(fits - 3, 0)] + "..."
        mask = text_mask(text)
        if centre_w is not None:
            x += max((centre_w - mask.shape[1]) // 2, 0)
        if right is not None:
            x = right - mask.shape[1]
        y = y_mid - (7 * SCALE) // 2
        h = min(mask.shape[0], self.img.shape[0] - y)
        w = min(mask.shape[1], self.img.shape[1] - x)
        self.img[y:y + h, x:x + w][mask[:h, :w]] = colour

    def triangle(self, x, y_mid, is_open, colour=TEXT):
        n = 3 * SCALE
        for i in range(n):
            if is_open:     # pointing down
                self.img[y_mid - n // 2 + i, x + i:x + 2 * n - i] = colour
            else:           # pointing right
                self.img[y_mid - n + i:y_mid + n - i, x + i] = colour


def _draw_item(cv: Canvas, it: dict, x0: int, x1: int, y: int) -> None:
    mid = y + ROW_H // 2
    w = x1 - x0
    if it["kind"] == "label":
        x = x0
        if it.get("icon") in ("INFO", "ERROR"):        # Blender's round info / warning icon
            cv.rect(x, mid - 5 * SCALE, x + 10 * SCALE, mid + 5 * SCALE,
                    (70, 110, 170) if it["icon"] == "INFO" else (190, 90, 60))
            cv.text(x + 2 * SCALE, mid, "i" if it["icon"] == "INFO" else "!", TEXT)
        if it.get("icon"):
            x += 13 * SCALE
        cv.text(x, mid, it["label"], TEXT, max_w=x1 - x)
        return
    top, bot = y + SCALE, y + ROW_H - SCALE
    if it["kind"] == "op":
        cv.rect(x0, top, x1, bot, BUTTON if it["enabled"] else MENU, BORDER)
        cv.text(x0, mid, it["label"], TEXT if it["enabled"] else DIM, max_w=w - PAD,
                centre_w=w)
        return
    kind, label, value = it["type"], it["label"], it["value"]
    if kind == "BOOLEAN":
        b = 10 * SCALE
        cv.rect(x0, mid - b // 2, x0 + b, mid + b // 2, CHECK if not value else (71, 114, 179),
                BORDER)
        if value:
            cv.text(x0 + 2 * SCALE, mid, "x", TEXT)
        cv.text(x0 + b + PAD, mid, label, TEXT, max_w=w - b - PAD)
    elif kind in ("INT", "FLOAT"):    # a number field: the label left, the value right
        cv.rect(x0, top, x1, bot, BUTTON, BORDER)
        cv.text(x0 + 2 * PAD, mid, label, TEXT, max_w=w // 2)
        cv.text(x0, mid, value, TEXT, right=x1 - 2 * PAD)
    else:   # ENUM (a menu) and STRING (a text field): the label to the left, as Blender does
        lw = int(w * 0.4)
        cv.text(x0, mid, f"{label}:", TEXT, max_w=lw - PAD)
        fx = x0 + lw
        if kind == "ENUM":
            cv.rect(fx, top, x1, bot, MENU, BORDER)
            cv.text(fx + PAD, mid, value, TEXT, max_w=x1 - fx - 4 * PAD)
            cv.triangle(x1 - 3 * PAD, mid, True, DIM)
        else:
            cv.rect(fx, top, x1, bot, FIELD, BORDER)
            shown, colour = (value, TEXT) if value else (it["placeholder"], DIM)
            cv.text(fx + PAD, mid, shown, colour, max_w=x1 - fx - 2 * PAD)


def draw(panels, width: int = 960) -> np.ndarray:
    """The recorded panels as an (H, W, 3) uint8 image."""
    height = PAD
    for _, is_open, _, rows in panels:
        height += ROW_H + PAD + (len(rows) * (ROW_H + SCALE) + PAD if is_open else 0)
    cv = Canvas(width, height + PAD)
    y = PAD
    for label, is_open, depth, rows in panels:
        indent = PAD + depth * 3 * SCALE
        cv.rect(indent, y, width - PAD, y + ROW_H + PAD, HEADER if depth == 0 else SUBHEADER)
        cv.triangle(indent + PAD, y + (ROW_H + PAD) // 2, is_open)
        cv.text(indent + 5 * PAD, y + (ROW_H + PAD) // 2, label, TEXT)
        y += ROW_H + PAD
        if not is_open:
            continue
        y += PAD // 2
        x0, x1 = indent + 2 * PAD, width - 3 * PAD
        boxed = [i for i, r in enumerate(rows) if any(it["boxed"] for it in r.items)]
        if boxed:   # a box (the object's data) behind its rows
            top = y + boxed[0] * (ROW_H + SCALE) - SCALE
            cv.rect(x0 - PAD, top, x1 + PAD, y + (boxed[-1] + 1) * (ROW_H + SCALE) + SCALE,
                    BOX, BORDER)
        for row in rows:
            n = len(row.items)
            gap = SCALE if n > 1 else 0
            span = (x1 - x0 - gap * (n - 1)) // n
            for k, it in enumerate(row.items):
                a = x0 + k * (span + gap)
                _draw_item(cv, it, a, a + span, y)
            y += ROW_H + SCALE
        y += PAD // 2
    return cv.img


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=os.path.join(ROOT, "docs", "images", "panel.png"))
    parser.add_argument("--rows", action="store_true", help="print the recorded rows")
    args = parser.parse_args(argv)
    # never the user's real Blender configuration (as the Makefile's targets)
    os.environ.setdefault("BLENDER_USER_RESOURCES", os.path.join(ROOT, "build", "blender-user"))
    from relightable_textures.lt_addon.io.contact_sheet import write_png

    context = fresh_scene()
    panels = record_panels(context)
    if args.rows:
        print(describe(panels))
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    n = write_png(args.out, draw(panels))
    print(f"panel_picture: {args.out} ({n} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
