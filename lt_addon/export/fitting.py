"""Fitting the exports, without Blender: L1 SH / MonoSH lightmaps projected from a transport
bake's T (with the texels' normals the bpy layer bakes), RTI PTM / HSH fitted to radiance
samples of a transport or lobes bake, their error at held-out normals and lights, and the file
names and read-back conventions (axes, decode) every format is written with.

The job (``operators/bakes/export.py``) opens the bake, bakes the normals with Cycles, and
writes the files; everything here is NumPy on arrays and bundles (:mod:`..transport.bundle`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..io.names import object_stem
from ..io import atomic, exrio, jpeg
from ..progress import Progress
from ..settings import check_ranges, setting
from ..sphere.directions import hemisphere_fibonacci, parse_direction_spec
from ..sphere.hemisphere import direction_from_az_el
from ..transport import texture as tt
from ..transport.bundle import relight, upsample
from ..transport.gathered_texture import indirect_images
from . import godot, rti, rti_files
from . import sh_lightmap as sh


FORMATS = ("sh-l1", "monosh", "godot-lightmap", "sun-indirect", "rti-ptm", "rti-hsh")
#: The formats baked for one lighting (--env or --sun).
LIGHTMAPS = ("sh-l1", "monosh", "godot-lightmap")


#: Tilts (degrees) of the held-out normals the SH formats are checked at (8 azimuths each).
TILTS = (0.0, 15.0, 30.0, 45.0)


#: Godot's axes (Y up, right-handed) from Blender's (Z up): (x, y, z)_godot = (x, z, -y).
BLENDER_TO_GODOT = godot.BLENDER_TO_GODOT


#: Unity's axes (Y up, left-handed) from Blender's: (x, y, z)_unity = (x, z, y).
BLENDER_TO_UNITY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])


#: How each lightmap format is read back (written into the files and the report).
DECODE = {
    "sh-l1": {
        "axes": "world frame in Godot's axes (Y up, right-handed): x, z, -y of Blender's world "
                "(as Blender's glTF exporter maps them)",
        "values": "L1 SH coefficients c_lm of incident radiance (W m^-2 sr^-1), linear Rec.709",
        "decode": "E/pi = 0.282095 L0 + 0.32573 (L1n1 n.y + L1_0 n.z + L1p1 n.x), n the world "
                  "normal (raw coefficients, as Godot 4.0-4.3's LightmapGI shader reads them; "
                  "--format godot-lightmap writes the files Godot loads)",
    },
    "monosh": {
        "axes": "world frame in Unity's axes (Y up, left-handed): x, z, y of Blender's world "
                "(as Unity's FBX/glTF importers place a Blender scene)",
        "values": "L0: ready-to-apply RGB (half EXR, linear); L1: luminance direction, 8-bit "
                  "PNG, linear data (import with sRGB off, no compression or high-quality BC7)",
        "decode": "Bakery MonoSH: nL1 = L1 * 2 - 1; E/pi = L0 + 2 L0 (nL1 . n) per channel, "
                  "n the world-space normal (z3y/ShaderGraph Bakery.hlsl)",
    },
    "godot-lightmap": {
        "axes": "the frame of a LightmapGI node at the origin: world, Godot's axes (x, z, -y "
                "of Blender's)",
        "values": "one half EXR, 4 layers stacked vertically (L0, L1 y, L1 z, L1 x), linear",
        "decode": {"4.4": "f(n) = L0 + 4 L0 (2 t - 1) . n, t = (L1y, L1z, L1x) layers "
                          "(packed, pre-convolved L1; _uses_packed_directional)",
                   "4.3": "f(n) = 0.282095 L0 + 0.32573 (L1y n.y + L1z n.z + L1x n.x) (raw)"},
    },
}


@dataclass
class ExportSettings:
    """What ``relight export`` fits and under which light (see the CLI's help)."""
    format: str = setting(label="Format", choices=(
        ("rti-hsh", "RTI HSH", "Hemispherical harmonics planes + a relightable web page "
                               "(relight tools' layout, as OpenLIME reads it)"),
        ("rti-ptm", "RTI PTM", "Polynomial texture map planes (6 terms) + a web page"),
        ("sh-l1", "L1 SH Lightmap", "Four half EXRs of L1 spherical harmonics (Godot's "
                                    "directional lightmap layers and axes), for one lighting"),
        ("monosh", "MonoSH Lightmap", "Bakery's MonoSH: L0 EXR + 8-bit direction (Unity "
                                      "axes), for one lighting"),
        ("godot-lightmap", "Godot Lightmap", "A folder Godot loads: stacked directional "
                                             "lightmap EXR + .import, LightmapGIData .tres, "
                                             "the object as glTF (UV2 = the bake's UVs) and a "
                                             "scene; for one lighting"),
        ("sun-indirect", "Sun-Moving Bounce", "The bounce light of a moving sun: a few basis "
                                              "lightmaps, a table of their weights over the "
                                              "sun's direction and a Godot shader")),
        help="What is exported")
    components: int | None = setting(None, metavar="K", panel=False,
                                     help="sun-indirect: basis lightmaps (1..8; default: the "
                                          "fewest whose held-out error is under 1 percent, at most 8)")
    godot: str = setting("4.4", choices=(("4.4", "Godot 4.4+", "Packed, pre-convolved L1"),
                                         ("4.3", "Godot 4.0-4.3", "Raw L1 coefficients")),
                         label="Godot", help="godot-lightmap: the Godot release it is for")
    terms: int | None = setting(None, metavar="K", panel=False,
                                help="rti-hsh: 4 or 9 (default) terms (OpenLIME evaluates at "
                                     "most 9; 16 is refused)")
    env: str | None = None              # SH formats: an equirect EXR ...
    rotate: float = setting(0.0, metavar="DEG", panel=False,
                            help="with --env: its rotation about +z, as a world Mapping node's Z")
    sun: tuple | None = None            # ... or a sun (azimuth, elevation) in degrees
    sun_angle: float = setting(0.0, lo=0.0, hi=30.0, metavar="DEG", panel=False,
                               help="SH formats: the sun's size in degrees")
    strength: float = setting(1.0, panel=False,
                              help="the light's strength (sun: W/m^2; env: a multiplier)")
    color: tuple = (1.0, 1.0, 1.0)
    exposure: float | None = setting(
        None, metavar="X", panel=False,
        help="RTI: radiance scale before sRGB encoding (default: the 99.5th percentile of the "
             "brightest lights maps to 1)")
    held_out: int = setting(16, lo=1, hi=1024, panel=False,
                            help="RTI: light directions off the baked ones the error is "
                                 "measured at")
    normal_samples: int = 4             # SH: Cycles samples of the normal bake

    def validate(self) -> None:
        if self.format not in FORMATS:
            raise InputError(f"format must be one of {', '.join(FORMATS)}, got "
                                 f"{self.format!r}")
        if self.format in LIGHTMAPS:
            if (self.env is None) == (self.sun is None):
                raise InputError(f"{self.format} is baked light for one lighting: give "
                                     "exactly one of --env HDR.exr and --sun AZ,EL")
        else:
            if self.env is not None or self.sun is not None:
                raise InputError(f"{self.format} keeps the light free (the viewer moves "
                                     "it): --env and --sun are for the SH formats")
        if self.components is not None and (self.format != "sun-indirect"
                                            or not 1 <= self.components <= 8):
            raise InputError("--components is for sun-indirect, 1..8")
        if self.format == "rti-hsh" and self.terms == 16:
            raise InputError("rti-hsh with 16 terms is not written: OpenLIME and the relight "
                             "tools evaluate 9 HSH terms and would drop terms 10-16 "
                             "silently; use --terms 9 (or 4)")
        if self.format == "rti-hsh" and self.terms not in (None, 4, 9):
            raise InputError(f"rti-hsh has 4 or 9 terms, got {self.terms}")
        if self.format == "rti-ptm" and self.terms not in (None, 6):
            raise InputError(f"rti-ptm has 6 terms, got {self.terms}")
        if not 0.0 <= self.sun_angle <= 30.0:
            raise InputError(f"sun angle must be in 0..30 degrees, got {self.sun_angle}")
        if self.strength <= 0:
            raise InputError(f"strength must be > 0, got {self.strength}")
        if self.exposure is not None and not self.exposure > 0:
            raise InputError(f"exposure must be > 0, got {self.exposure}")
        if not 1 <= self.held_out <= 1024:
            raise InputError(f"held-out lights must be in 1..1024, got {self.held_out}")
        check_ranges(self)

    @property
    def kind(self) -> str:
        return {"rti-ptm": "ptm", "rti-hsh": "hsh"}.get(self.format, "")


def output_stem(obj_name: str, settings: "ExportSettings") -> str:
    """``<object>_<format>``; HSH adds its term count (``_rti-hsh9``)."""
    fmt = settings.format
    if fmt == "rti-hsh":
        fmt += str(settings.terms or 9)
    return f"{object_stem(obj_name)}_{fmt}"


def output_names(obj_name: str, settings: "ExportSettings") -> list:
    """The files (relative to the output folder) an export writes."""
    base, fmt = output_stem(obj_name, settings), settings.format
    if fmt == "sh-l1":
        return [f"{base}_{k}.exr" for k in ("L0", "L1n1", "L1_0", "L1p1")] + [base + ".json"]
    if fmt == "monosh":
        return [f"{base}_L0.exr", f"{base}_L1.png", base + ".json"]
    return [base, base + ".json"]              # a folder (RTI: info.json, planes, index.html)


def read_environment(path: str) -> np.ndarray:
    """An equirect RGB EXR as (H, W, 3), row 0 at the bottom; InputError if unreadable."""
    try:
        ch, _ = exrio.read_exr(path)
    except Exception as exc:     # not an EXR, unreadable
        raise InputError(f"cannot read {path} as an EXR environment: {exc}") from None
    if not {"R", "G", "B"} <= set(ch):
        raise InputError(f"{path} has no R, G, B channels")
    return np.stack([ch[c] for c in "RGB"], axis=-1)


def light_weights(settings: ExportSettings, dset, kernel: str) -> np.ndarray:
    """``L(w_s) dw_s`` per baked direction, (S, 3) float64, for the SH formats' lighting."""
    tint = np.asarray(settings.color, np.float64) * settings.strength
    if settings.env is not None:
        env = read_environment(settings.env)
        w = tt.environment_weights(dset, env, row_order="bottom_first",
                                   rotation_deg=-settings.rotate)   # Mapping convention
        return w * tint
    idx, k = tt.sun_weights(dset, direction_from_az_el(*settings.sun), settings.sun_angle,
                            kernel)
    w = np.zeros(dset.size)
    np.add.at(w, idx, k)
    return w[:, None] * tint


def indirect_over_pi(bake, store, settings, kernel: str = "linear") -> np.ndarray | None:
    """Bounce light as ``E_ind / pi`` (P, 3) under the sun (None for an environment: the bake's
    indirect term is tabulated per sun direction only)."""
    if bake.indirect is None or settings.sun is None:
        return None
    rad = upsample(indirect_images(bake.indirect, direction_from_az_el(*settings.sun),
                                   settings.sun_angle, kernel),
                   store.resolution).reshape(-1, 3).astype(np.float64)
    albedo = bake.albedo.reshape(-1, 3).astype(np.float64)
    tint = np.asarray(settings.color, np.float64) * settings.strength
    return np.where(albedo > 0.02, rad / np.maximum(albedo, 0.02), 0.0) * tint


def sh_export(T, dset, weights, normals, indirect, variants=None):
    """Per-texel SH (P, 4, 3) and the error figures at held-out normals.

    T: (S, P) float16 store array; weights (S, 3); normals (P, 3) world (zero: uncovered).
    ``variants``: {name: f(SH (n, 4, 3)) -> SH (n, 4, 3)}, further stored forms whose error
    is measured the same way (e.g. Godot's packed layers as its shader decodes them).
    Streams over texel chunks (float64 working set of about ``tt.CHUNK_BYTES`` each)."""
    S, P = T.shape
    covered = np.linalg.norm(normals, axis=1) > 0
    L = np.zeros((P, 4, 3))
    az = np.arange(8) * 45.0 + 22.5
    variants = variants or {}
    sums = {t: {"sh": 0.0, "monosh": 0.0, "sh_half": 0.0, "ref": 0.0, **{k: 0.0 for k in variants}}
            for t in TILTS}
    step = tt.chunk_texels(S)
    for a in range(0, P, step):
        sl = slice(a, min(P, a + step))
        idx = np.flatnonzero(covered[sl]) + a
        if idx.size == 0:
            continue
        Tc = np.asarray(T[:, idx], np.float64)
        n = normals[idx]
        ind = None if indirect is None else indirect[idx]
        Lc = sh.project(Tc, dset.directions, weights, n, ind)
        L[idx] = Lc
        Lh = Lc.astype(np.float16).astype(np.float64)
        L0m, dm = sh.to_monosh(Lh)                       # as stored: half L0, 8-bit direction
        Lm = sh.from_monosh(L0m.astype(np.float16).astype(np.float64), np.rint(dm * 255) / 255)
        Lv = {k: f(Lc) for k, f in variants.items()}
        for tilt in TILTS:
            for phi in (az if tilt > 0 else az[:1]):
                n2 = sh.tilted_normals(n, tilt, phi)
                ref = sh.reference_irradiance(Tc, dset.directions, weights, n, n2, ind)
                s = sums[tilt]
                s["ref"] += float(np.sum(ref ** 2))
                s["sh"] += float(np.sum((sh.irradiance(Lc, n2).clip(0) - ref) ** 2))
                s["sh_half"] += float(np.sum((sh.irradiance(Lh, n2).clip(0) - ref) ** 2))
                s["monosh"] += float(np.sum((sh.irradiance(Lm, n2).clip(0) - ref) ** 2))
                for k, Lk in Lv.items():
                    s[k] += float(np.sum((sh.irradiance(Lk, n2).clip(0) - ref) ** 2))
    errors = {}
    for key in ("sh_half", "monosh", *variants):
        errors[key] = {f"tilt_{int(t)}": round(float(np.sqrt(sums[t][key] / sums[t]["ref"])), 5)
                       if sums[t]["ref"] > 0 else None for t in TILTS}
    errors["sh_float64"] = {f"tilt_{int(t)}": round(float(np.sqrt(sums[t]["sh"]
                                                                   / sums[t]["ref"])), 5)
                            if sums[t]["ref"] > 0 else None for t in TILTS}
    return L, errors, int(covered.sum())


def godot_layers(L_world) -> dict:
    """The sh-l1 format's four layers (each (P, 3)) from world-frame SH (P, 4, 3): Godot
    4.3's raw layers (:func:`.godot.encode`), decoded as
    ``0.282095 L0 + 0.32573 (L1n1 n.y + L1_0 n.z + L1p1 n.x)`` with the world normal."""
    lay = godot.encode(L_world, "4.3")
    return {"L0": lay[0], "L1n1": lay[1], "L1_0": lay[2], "L1p1": lay[3]}


def held_out_lights(count: int) -> np.ndarray:
    """``count`` light directions (count, 3) over the hemisphere above 10 degrees of
    elevation, turned 17 degrees off the bake's own Fibonacci sets (so none is a baked one)."""
    d = hemisphere_fibonacci(count).directions.copy()
    el = np.arcsin(np.clip(d[:, 2], 0, 1))
    el = np.radians(10.0) + el * (np.pi / 2 - np.radians(10.0)) / (np.pi / 2)
    az = np.arctan2(d[:, 1], d[:, 0]) + np.radians(17.0)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)


def radiance_at(bake, store, s_index: int, T) -> np.ndarray:
    """Radiance (P, 3) under a unit sun exactly at baked direction ``s_index``."""
    out = np.asarray(T[s_index], np.float64)[:, None] * bake.albedo.reshape(-1, 3)
    if bake.indirect is not None:
        d = store.directions.directions[s_index]
        out = out + upsample(bake.indirect.relight(d), store.resolution).reshape(-1, 3)
    return out


@dataclass
class RadianceSource:
    """What an RTI fit samples: radiance (P, 3) of every texel under a unit white sun, at the
    ``lights`` (a DirectionSet with solid angles) by index, and at any direction (for the
    held-out lights); ``resolution`` R with P = R * R, row 0 at v = 0."""
    lights: object
    at_sample: object          # s -> (P, 3)
    at_direction: object       # (3,) -> (P, 3)
    resolution: int
    what: str


def transport_source(bake, store, kernel: str) -> RadianceSource:
    """A transport-texture bake: the baked suns exactly, other lights by its own relight."""
    return RadianceSource(
        store.directions, lambda s: radiance_at(bake, store, s, store.array),
        lambda d: relight(bake, store, d, 0.0, source="transport",
                          kernel=kernel).reshape(-1, 3).astype(np.float64),
        store.resolution, "transport texture (with its bounce term)")


#: Lights a lobes bake is sampled at for an RTI fit (its relight is smooth in the light).
LOBES_LIGHTS = "hemi:400:1.5"


def lobes_source(texture) -> RadianceSource:
    """A steerable (lobes) bake: its relight sampled at LOBES_LIGHTS."""
    dset = parse_direction_spec(LOBES_LIGHTS)

    def at(d):
        return np.asarray(texture.relight(np.asarray(d, np.float64)),
                          np.float64).reshape(-1, 3)
    return RadianceSource(dset, lambda s: at(dset.directions[s]), at,
                          int(texture.basis_images.shape[1]), "steerable lobes bake")


def rti_export(source: RadianceSource, settings, progress_every=None):
    """Fit ``settings.kind`` to the source's display values at its lights (HSH: those at or
    above the viewers' clamp elevation);
    returns the 8-bit planes (P, K, 3) with scale and bias, the exposure used and the errors
    at held-out lights.

    Radiance under a unit white sun is scaled by the exposure and sRGB-encoded (what a camera
    records; the RTI field fits its bases to such images), then fitted by weighted least
    squares (weights: the lights' solid angles) one light at a time."""
    dset = source.lights
    terms = settings.terms or (6 if settings.kind == "ptm" else 9)
    # HSH: only the lights at or above the viewers' clamp. Below it OpenLIME (and our page)
    # show the clamp elevation's image, so fitting them there only averages darker samples
    # into it (measured on the bumps demo, 1600 suns: held-out RMSE 0.0758 -> 0.0713)
    # PTM: the lights above the horizon (a bake's band under it mirrors lights of the same
    # (lu, lv), for a wide sun's disc only)
    fitted = (np.flatnonzero(dset.directions[:, 2] >= np.sin(rti.HSH_MIN_ELEVATION) - 1e-12)
              if settings.kind == "hsh" else np.flatnonzero(dset.directions[:, 2] > 0.0))
    lights, solid = dset.directions[fitted], dset.solid_angles[fitted]
    B = rti.basis(settings.kind, lights, terms)                          # (S', K)
    sw = np.sqrt(solid)
    Bw = B * sw[:, None]
    cond = float(np.linalg.cond(Bw))
    if cond > rti.MAX_CONDITION:
        raise InputError(f"{settings.format} with {terms} terms is ill-conditioned on the "
                             f"bake's {fitted.size} directions (condition {cond:.3g})")
    M = np.linalg.pinv(Bw) * sw[None, :]                                 # (K, S')
    exposure = settings.exposure
    if exposure is None:
        top = np.argsort(dset.directions[:, 2])[-8:]
        sample = np.concatenate([source.at_sample(int(s)) for s in top])
        p = float(np.percentile(sample, 99.5))
        exposure = 1.0 / p if p > 0 else 1.0
    R = source.resolution
    P = R * R
    coef = np.zeros((P, terms, 3))
    for j, s in enumerate(fitted):
        v = rti.to_display(source.at_sample(int(s)), exposure)
        coef += M[:, j][None, :, None] * v[:, None, :]
        if progress_every and j % progress_every == 0:
            yield Progress(j, fitted.size,
                           f"fitting {settings.format}: light {j + 1}/{fitted.size}")
    coef, nonneg = rti.keep_nonnegative(coef, settings.kind, lights, solid)
    q, scale, bias = rti.quantize(coef)
    deq = rti.dequantize(q, scale, bias)
    # what the files hold: the planes as a JPEG decoder shows them (rows top first on disk)
    qj = np.stack([jpeg.reconstruct(np.ascontiguousarray(q[:, k].reshape(R, R, 3)[::-1]),
                                    rti_files.JPEG_QUALITY)[::-1].reshape(P, 3)
                   for k in range(terms)], axis=1)
    deq_jpeg = rti.dequantize(qj, scale, bias)
    per_light, planes_8bit, negative = [], [], 0
    for d in held_out_lights(settings.held_out):
        truth = rti.to_display(source.at_direction(d), exposure)
        raw = rti.evaluate(deq_jpeg, d, settings.kind)
        negative += int(np.count_nonzero(raw < 0))
        e, psnr = rti.rmse_psnr(np.clip(raw, 0.0, 1.0), truth)
        per_light.append({"light": [round(float(x), 4) for x in d], "rmse": round(e, 5),
                          "psnr_db": round(psnr, 2)})
        planes_8bit.append(rti.rmse_psnr(np.clip(rti.evaluate(deq, d, settings.kind), 0, 1),
                                         truth)[0])
    rm = [p["rmse"] for p in per_light]
    errors = {"held_out_lights": len(per_light), "rmse_mean": round(float(np.mean(rm)), 5),
              "rmse_max": round(float(np.max(rm)), 5),
              "psnr_mean_db": round(float(np.mean([p["psnr_db"] for p in per_light])), 2),
              "rmse_mean_lossless_8bit_planes": round(float(np.mean(planes_8bit)), 5),
              "jpeg_quality": rti_files.JPEG_QUALITY,
              "negative_values_at_held_out_lights": negative,
              "nonnegative_fit": nonneg,
              "fitted_lights": int(fitted.size),
              "per_light": per_light, "design_condition": round(cond, 2)}
    return q, scale, bias, exposure, errors
