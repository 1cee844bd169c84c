"""RTI files on disk (bpy-free): the relight tools' layout plus a self-contained web page.

A folder holds

* ``info.json`` -- as the relight tools write it and OpenLIME reads it: ``width``,
  ``height``, ``format`` ("jpg"), ``type`` ("ptm" or "hsh"), ``colorspace`` ("rgb"),
  ``nplanes`` (3 x terms), ``materials[0].scale`` and ``.bias`` (one per plane, plane
  ``3 k + c`` = coefficient ``k`` of channel ``c``); and ours: ``exposure``, ``values``
  ("srgb display"), ``light_frame``;
* ``plane_<k>.jpg`` -- coefficient ``k`` of R, G, B as an 8-bit RGB image, top row first
  (texture v = 1), ``c = (q / 255 - bias) * scale``. JPEG because OpenLIME and the relight
  tools request ``plane_<k>.jpg`` whatever ``format`` says; written by our own encoder
  (:mod:`..io.jpeg`) at JPEG_QUALITY with no chroma subsampling (a plane's "colour" is three
  channels' coefficients, not a colour);
* ``index.html`` -- a page that embeds the above and relights it with the mouse
  (``web/viewer.js``): it opens from disk or any static host, no server or package needed.

:func:`relight` is the viewer's arithmetic in NumPy (the test compares the two pixel by pixel).
"""

from __future__ import annotations

import base64
import html
import json
import os

import numpy as np

from ..errors import InputError
from ..io import atomic, jpeg
from ..io.contact_sheet import read_png
from . import rti

FORMAT = "relightable_textures.rti"
WEB = os.path.join(os.path.dirname(__file__), "web")
#: JPEG quality of the planes (IJG scale, 4:4:4). Measured on the bumps demo's HSH planes
#: (docs/exports.md): see JPEG_ERROR_NOTE.
JPEG_QUALITY = 95


def write(folder: str, q, scale, bias, kind: str, *, exposure: float = 1.0,
          title: str = "Relightable texture", quality: int = JPEG_QUALITY) -> str:
    """Write an RTI folder atomically (built under a temporary name, renamed when complete;
    an existing folder of that name is replaced).

    Parameters
    ----------
    q : (R, R, K, 3) uint8, row 0 at texture v = 0 (as our textures)
    scale, bias : (K, 3) float64 (see :func:`.rti.quantize`)
    kind : "ptm" or "hsh"

    Returns the folder's absolute path.
    """
    q = np.asarray(q, np.uint8)
    H, W, K, C = q.shape
    if C != 3:
        raise ValueError(f"expected RGB coefficients, got {C} channels")
    folder = os.path.abspath(folder)
    with atomic.staged_folder(folder) as tmp:
        info = {"width": W, "height": H, "format": "jpg", "type": kind, "colorspace": "rgb",
                "nplanes": 3 * K,
                "materials": [{"scale": [float(v) for v in np.asarray(scale).reshape(-1)],
                               "bias": [float(v) for v in np.asarray(bias).reshape(-1)]}],
                "exposure": float(exposure), "values": "srgb display",
                "light_frame": "x right, y up (texture u, v), z out of the surface",
                "writer": FORMAT}
        atomic.write_json(os.path.join(tmp, "info.json"), info, indent=1)
        uris = []
        for k in range(K):
            img = q[::-1, :, k, :]                                   # top row first
            data = jpeg.encode(np.ascontiguousarray(img), quality)
            with open(os.path.join(tmp, f"plane_{k}.jpg"), "wb") as fh:
                fh.write(data)
            uris.append("data:image/jpeg;base64," + base64.b64encode(data).decode("ascii"))
        with open(os.path.join(WEB, "template.html")) as fh:
            page = fh.read()
        with open(os.path.join(WEB, "viewer.js")) as fh:
            js = fh.read()
        page = (page.replace("{{TITLE}}", html.escape(title))
                .replace("{{INFO}}", json.dumps(info).replace("</", "<\\/"))
                .replace("{{PLANES}}", json.dumps(uris))
                .replace("{{VIEWER}}", js))
        atomic.write_text(os.path.join(tmp, "index.html"), page)
    return folder


def _read_plane(folder: str, k: int, fmt: str) -> np.ndarray:
    if fmt == "png":
        return read_png(os.path.join(folder, f"plane_{k}.png"))
    try:
        from PIL import Image
    except ImportError:
        raise InputError("reading JPEG planes needs Pillow (pip install pillow); Blender "
                         "does not ship it") from None
    with Image.open(os.path.join(folder, f"plane_{k}.jpg")) as im:
        return np.asarray(im.convert("RGB"))


def read(folder: str):
    """(q (R, R, K, 3) uint8 with row 0 at v = 0, scale (K, 3), bias (K, 3), info) of a folder
    written by :func:`write` (or any relight-layout rgb PTM/HSH folder with JPEG or PNG
    planes; JPEG is decoded with Pillow, a development dependency)."""
    from ..io import untrusted as ut

    path = ut.confined(folder, "info.json", must_exist=True, folder=False)
    info = ut.read_json(path)       # (a folder from elsewhere: capped, typed, one line)
    if info.get("colorspace") != "rgb" or info.get("type") not in ("ptm", "hsh"):
        raise ut.UntrustedFileError(path, f"only rgb PTM/HSH planes are read, got "
                                          f"{info.get('type')!r:.20}/"
                                          f"{info.get('colorspace')!r:.20}")
    K = ut.check_count(path, ut.field(info, "nplanes", path, int), 3 * 64, "nplanes", lo=3) // 3
    fmt = ut.field(info, "format", path, str, "jpg")
    if fmt not in ("jpg", "png"):
        raise ut.UntrustedFileError(path, f"format {fmt!r:.20} is not jpg or png")
    for k in range(K):
        ut.confined(folder, f"plane_{k}.{fmt}", must_exist=True, folder=False)
    planes = [_read_plane(folder, k, fmt)[::-1] for k in range(K)]
    if len({p.shape for p in planes}) != 1:
        raise ut.UntrustedFileError(path, "its planes differ in size")
    q = np.stack(planes, axis=2)
    try:
        mat = ut.field(info, "materials", path, list)[0]
        scale = np.asarray(ut.field(mat, "scale", path, list, where="materials[0]"),
                           np.float64).reshape(K, 3)
        bias = np.asarray(ut.field(mat, "bias", path, list, where="materials[0]"),
                          np.float64).reshape(K, 3)
    except (IndexError, ValueError, TypeError) as exc:
        if isinstance(exc, ut.UntrustedFileError):
            raise
        raise ut.UntrustedFileError(path, f"its materials' scale and bias are not {K} x 3 "
                                          "numbers") from None
    ut.check_values(path, scale, what="scales")
    ut.check_values(path, bias, what="biases")
    return q, scale, bias, info


def relight(folder: str, light) -> np.ndarray:
    """The page's picture at ``light`` (3,): (H, W, 3) uint8, top row first, computed as the
    viewer does (float64 coefficients, clamp, round)."""
    q, scale, bias, info = read(folder)
    H, W, K, _ = q.shape
    coef = rti.dequantize(q.reshape(H * W, K, 3), scale, bias)
    v = rti.evaluate(coef, np.asarray(light, np.float64), info["type"])
    img = np.rint(np.clip(v, 0.0, 1.0) * 255.0).astype(np.uint8).reshape(H, W, 3)
    return img[::-1]
