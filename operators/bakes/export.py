"""Take a relightable bake out of Blender (``relight export``): directional lightmaps for game
engines (L1 SH, MonoSH) and RTI models (PTM, HSH) with a relightable web page, fitted from an
object's transport-texture bake, each with its error against our own relight.

The job reads the bake (``texture_transport.load_bake``); the SH formats also bake the texels'
shading normals with Cycles (one NORMAL bake) because their projection needs the visibility
``V = pi T / cos`` (see :mod:`..lt_addon.export.sh_lightmap`). Formats and fitting live in
``lt_addon/export``; this module is the bpy side: the scene, the object's frame, files.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ...lt_addon.export import rti, rti_files
from ...lt_addon.export import sh_lightmap as sh
from ...lt_addon.io import atomic, exrio
from ...lt_addon.io.contact_sheet import write_png
from ...lt_addon.sphere.directions import hemisphere_fibonacci
from ...lt_addon.sphere.hemisphere import direction_from_az_el
from ...lt_addon.transport import texture as tt
from ..base import cycles_device
from ..base.cycles_bake import BakeInputError
from ..base.jobs import Progress

FORMATS = ("sh-l1", "monosh", "rti-ptm", "rti-hsh")
KIND = "export"
#: Tilts (degrees) of the held-out normals the SH formats are checked at (8 azimuths each).
TILTS = (0.0, 15.0, 30.0, 45.0)
#: Godot's axes (Y up, right-handed) from Blender's (Z up): (x, y, z)_godot = (x, z, -y).
BLENDER_TO_GODOT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: Unity's axes (Y up, left-handed) from Blender's: (x, y, z)_unity = (x, z, y).
BLENDER_TO_UNITY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])


#: How each lightmap format is read back (written into the files and the report).
DECODE = {
    "sh-l1": {
        "axes": "Godot (Y up): x, z, -y of the object's own Blender frame",
        "values": "L1 SH coefficients c_lm of incident radiance (W m^-2 sr^-1), linear Rec.709",
        "decode": "E/pi = 0.282095 L0 + 0.32573 (L1n1 n.y + L1_0 n.z + L1p1 n.x), n in the "
                  "object's frame (Godot 4's LightmapGI shader with raw coefficients; builds "
                  "that store pre-convolved terms want L0 * 0.282095 and L1 * 0.325735)",
    },
    "monosh": {
        "axes": "Unity (Y up, left-handed): x, z, y of the object's own Blender frame",
        "values": "L0: ready-to-apply RGB (half EXR); L1: luminance direction, 8-bit PNG",
        "decode": "Bakery MonoSH: nL1 = L1 * 2 - 1; E/pi = L0 + 2 L0 (nL1 . n) per channel",
    },
}


@dataclass
class ExportSettings:
    """What ``relight export`` fits and under which light (see the CLI's help)."""
    format: str
    terms: int | None = None            # rti-hsh: 4, 9 or 16 (default 9)
    env: str | None = None              # SH formats: an equirect EXR ...
    rotate: float = 0.0                 # ... turned like a world Mapping node's Z rotation
    sun: tuple | None = None            # ... or a sun (azimuth, elevation) in degrees
    sun_angle: float = 0.0
    strength: float = 1.0
    color: tuple = (1.0, 1.0, 1.0)
    exposure: float | None = None       # RTI: display scale (default: 99.5th percentile -> 1)
    held_out: int = 16                  # RTI: held-out lights the error is measured at
    normal_samples: int = 4             # SH: Cycles samples of the normal bake

    def validate(self) -> None:
        if self.format not in FORMATS:
            raise BakeInputError(f"format must be one of {', '.join(FORMATS)}, got "
                                 f"{self.format!r}")
        if self.format.startswith("sh") or self.format == "monosh":
            if (self.env is None) == (self.sun is None):
                raise BakeInputError(f"{self.format} is baked light for one lighting: give "
                                     "exactly one of --env HDR.exr and --sun AZ,EL")
        else:
            if self.env is not None or self.sun is not None:
                raise BakeInputError(f"{self.format} keeps the light free (the viewer moves "
                                     "it): --env and --sun are for the SH formats")
        if self.format == "rti-hsh" and self.terms not in (None, 4, 9, 16):
            raise BakeInputError(f"rti-hsh has 4, 9 or 16 terms, got {self.terms}")
        if self.format == "rti-ptm" and self.terms not in (None, 6):
            raise BakeInputError(f"rti-ptm has 6 terms, got {self.terms}")
        if not 0.0 <= self.sun_angle <= 30.0:
            raise BakeInputError(f"sun angle must be in 0..30 degrees, got {self.sun_angle}")
        if self.strength <= 0:
            raise BakeInputError(f"strength must be > 0, got {self.strength}")
        if self.exposure is not None and not self.exposure > 0:
            raise BakeInputError(f"exposure must be > 0, got {self.exposure}")
        if not 1 <= self.held_out <= 1024:
            raise BakeInputError(f"held-out lights must be in 1..1024, got {self.held_out}")

    @property
    def kind(self) -> str:
        return {"rti-ptm": "ptm", "rti-hsh": "hsh"}.get(self.format, "")


@dataclass
class ExportOutput:
    """A finished export: its report (also written as ``<object>_<format>.json``) and files."""
    report: dict
    files: dict = field(default_factory=dict)


def output_stem(obj_name: str, settings: "ExportSettings") -> str:
    """``<object>_<format>``; HSH adds its term count (``_rti-hsh9``)."""
    fmt = settings.format
    if fmt == "rti-hsh":
        fmt += str(settings.terms or 9)
    return f"{atomic.safe_name(obj_name)}_{fmt}"


def output_names(obj_name: str, settings: "ExportSettings") -> list:
    """The files (relative to the output folder) an export writes."""
    base, fmt = output_stem(obj_name, settings), settings.format
    if fmt == "sh-l1":
        return [f"{base}_{k}.exr" for k in ("L0", "L1n1", "L1_0", "L1p1")] + [base + ".json"]
    if fmt == "monosh":
        return [f"{base}_L0.exr", f"{base}_L1.png", base + ".json"]
    return [base, base + ".json"]              # a folder (info.json, planes, index.html)


# ----------------------------------------------------------------------------------------------
# inputs


def read_environment(path: str) -> np.ndarray:
    """An equirect RGB EXR as (H, W, 3), row 0 at the bottom; BakeInputError if unreadable."""
    try:
        ch, _ = exrio.read_exr(path)
    except Exception as exc:     # not an EXR, unreadable
        raise BakeInputError(f"cannot read {path} as an EXR environment: {exc}") from None
    if not {"R", "G", "B"} <= set(ch):
        raise BakeInputError(f"{path} has no R, G, B channels")
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


def texel_normals(scene, obj, resolution: int, samples: int) -> np.ndarray:
    """World-frame shading normals (P, 3) of ``obj``'s texels from a Cycles NORMAL bake (zero
    vectors where no UV island or margin lies)."""
    from ..base.cycles_bake import EnvironmentBake

    with EnvironmentBake(scene, obj, resolution, samples, 0, (4, 8)) as b:
        n_obj = b.bake_normals()[0].reshape(-1, 3)
    M = np.array(obj.matrix_world, np.float64)[:3, :3]
    n = n_obj @ np.linalg.inv(M)             # (M^-T n)^T = n^T M^-1
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.maximum(length, 1e-12), 0.0)


def object_rotation(obj) -> np.ndarray:
    """The rotation (3, 3) of ``obj``'s world matrix (scale removed)."""
    M = np.array(obj.matrix_world, np.float64)[:3, :3]
    u, _, vt = np.linalg.svd(M)
    return u @ vt


# ----------------------------------------------------------------------------------------------
# SH lightmaps


def _indirect_over_pi(bake, store, settings) -> np.ndarray | None:
    """Bounce light as ``E_ind / pi`` (P, 3) under the sun (None for an environment: the bake's
    indirect term is tabulated per sun direction only)."""
    from ...lt_addon.transport.bundle import upsample as _upsample

    if bake.indirect is None or settings.sun is None:
        return None
    rad = _upsample(bake.indirect.relight(direction_from_az_el(*settings.sun)),
                    store.resolution).reshape(-1, 3).astype(np.float64)
    albedo = bake.albedo.reshape(-1, 3).astype(np.float64)
    tint = np.asarray(settings.color, np.float64) * settings.strength
    return np.where(albedo > 0.02, rad / np.maximum(albedo, 0.02), 0.0) * tint


def sh_export(T, dset, weights, normals, indirect):
    """Per-texel SH (P, 4, 3) and the error figures at held-out normals.

    T: (S, P) float16 store array; weights (S, 3); normals (P, 3) world (zero: uncovered).
    Streams over texel chunks (float64 working set of about ``tt.CHUNK_BYTES`` each)."""
    S, P = T.shape
    covered = np.linalg.norm(normals, axis=1) > 0
    L = np.zeros((P, 4, 3))
    az = np.arange(8) * 45.0 + 22.5
    sums = {t: {"sh": 0.0, "monosh": 0.0, "sh_half": 0.0, "ref": 0.0} for t in TILTS}
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
        for tilt in TILTS:
            for phi in (az if tilt > 0 else az[:1]):
                n2 = sh.tilted_normals(n, tilt, phi)
                ref = sh.reference_irradiance(Tc, dset.directions, weights, n, n2, ind)
                s = sums[tilt]
                s["ref"] += float(np.sum(ref ** 2))
                s["sh"] += float(np.sum((sh.irradiance(Lc, n2).clip(0) - ref) ** 2))
                s["sh_half"] += float(np.sum((sh.irradiance(Lh, n2).clip(0) - ref) ** 2))
                s["monosh"] += float(np.sum((sh.irradiance(Lm, n2).clip(0) - ref) ** 2))
    errors = {}
    for key in ("sh_half", "monosh"):
        errors[key] = {f"tilt_{int(t)}": round(float(np.sqrt(sums[t][key] / sums[t]["ref"])), 5)
                       if sums[t]["ref"] > 0 else None for t in TILTS}
    errors["sh_float64"] = {f"tilt_{int(t)}": round(float(np.sqrt(sums[t]["sh"]
                                                                   / sums[t]["ref"])), 5)
                            if sums[t]["ref"] > 0 else None for t in TILTS}
    return L, errors, int(covered.sum())


def godot_layers(L_world, rotation) -> dict:
    """Godot's four lightmap layers (each (P, 3)) from world-frame SH (P, 4, 3): the L1 vector
    turned into the object's frame, then into Godot's axes (Y up); Godot evaluates
    ``0.282095 L0 + 0.32573 (L1n1 n.y + L1_0 n.z + L1p1 n.x)`` with the object-space normal."""
    vec = np.stack([L_world[:, 3], L_world[:, 1], L_world[:, 2]], axis=1)   # (P, xyz, 3)
    local = np.einsum("ji,pjc->pic", rotation, vec)                          # R^T v
    g = np.einsum("ij,pjc->pic", BLENDER_TO_GODOT, local)
    return {"L0": L_world[:, 0], "L1n1": g[:, 1], "L1_0": g[:, 2], "L1p1": g[:, 0]}


# ----------------------------------------------------------------------------------------------
# RTI


def held_out_lights(count: int) -> np.ndarray:
    """``count`` light directions (count, 3) over the hemisphere above 10 degrees of
    elevation, turned 17 degrees off the bake's own Fibonacci sets (so none is a baked one)."""
    d = hemisphere_fibonacci(count).directions.copy()
    el = np.arcsin(np.clip(d[:, 2], 0, 1))
    el = np.radians(10.0) + el * (np.pi / 2 - np.radians(10.0)) / (np.pi / 2)
    az = np.arctan2(d[:, 1], d[:, 0]) + np.radians(17.0)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)


def _radiance_at(bake, store, s_index: int, T) -> np.ndarray:
    """Radiance (P, 3) under a unit sun exactly at baked direction ``s_index``."""
    from ...lt_addon.transport.bundle import upsample as _upsample

    out = np.asarray(T[s_index], np.float64)[:, None] * bake.albedo.reshape(-1, 3)
    if bake.indirect is not None:
        d = store.directions.directions[s_index]
        out = out + _upsample(bake.indirect.relight(d), store.resolution).reshape(-1, 3)
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
    from .texture_transport import relight

    return RadianceSource(
        store.directions, lambda s: _radiance_at(bake, store, s, store.array),
        lambda d: relight(bake, store, d, 0.0, source="transport",
                          kernel=kernel).reshape(-1, 3).astype(np.float64),
        store.resolution, "transport texture (with its bounce term)")


#: Lights a lobes bake is sampled at for an RTI fit (its relight is smooth in the light).
LOBES_LIGHTS = "hemi:400:1.5"


def lobes_source(texture) -> RadianceSource:
    """A steerable (lobes) bake: its relight sampled at LOBES_LIGHTS."""
    from ...lt_addon.sphere.directions import parse_direction_spec

    dset = parse_direction_spec(LOBES_LIGHTS)

    def at(d):
        return np.asarray(texture.relight(np.asarray(d, np.float64)),
                          np.float64).reshape(-1, 3)
    return RadianceSource(dset, lambda s: at(dset.directions[s]), at,
                          int(texture.basis_images.shape[1]), "steerable lobes bake")


def rti_export(source: RadianceSource, settings, progress_every=None):
    """Fit ``settings.kind`` to the source's display values at every one of its lights;
    returns the 8-bit planes (P, K, 3) with scale and bias, the exposure used and the errors
    at held-out lights.

    Radiance under a unit white sun is scaled by the exposure and sRGB-encoded (what a camera
    records; the RTI field fits its bases to such images), then fitted by weighted least
    squares (weights: the lights' solid angles) one light at a time."""
    dset = source.lights
    terms = settings.terms or (6 if settings.kind == "ptm" else 9)
    B = rti.basis(settings.kind, dset.directions, terms)                 # (S, K)
    sw = np.sqrt(dset.solid_angles)
    Bw = B * sw[:, None]
    cond = float(np.linalg.cond(Bw))
    if cond > rti.MAX_CONDITION:
        raise BakeInputError(f"{settings.format} with {terms} terms is ill-conditioned on the "
                             f"bake's {dset.size} directions (condition {cond:.3g})")
    M = np.linalg.pinv(Bw) * sw[None, :]                                 # (K, S)
    exposure = settings.exposure
    if exposure is None:
        top = np.argsort(dset.directions[:, 2])[-8:]
        sample = np.concatenate([source.at_sample(int(s)) for s in top])
        p = float(np.percentile(sample, 99.5))
        exposure = 1.0 / p if p > 0 else 1.0
    P = source.resolution ** 2
    coef = np.zeros((P, terms, 3))
    for s in range(dset.size):
        v = rti.to_display(source.at_sample(s), exposure)
        coef += M[:, s][None, :, None] * v[:, None, :]
        if progress_every and s % progress_every == 0:
            yield Progress(s, dset.size, f"fitting {settings.format}: light {s + 1}/{dset.size}")
    q, scale, bias = rti.quantize(coef)
    deq = rti.dequantize(q, scale, bias)
    per_light = []
    for d in held_out_lights(settings.held_out):
        truth = rti.to_display(source.at_direction(d), exposure)
        est = np.clip(rti.evaluate(deq, d, settings.kind), 0.0, 1.0)
        e, psnr = rti.rmse_psnr(est, truth)
        per_light.append({"light": [round(float(x), 4) for x in d], "rmse": round(e, 5),
                          "psnr_db": round(psnr, 2)})
    rm = [p["rmse"] for p in per_light]
    errors = {"held_out_lights": len(per_light), "rmse_mean": round(float(np.mean(rm)), 5),
              "rmse_max": round(float(np.max(rm)), 5),
              "psnr_mean_db": round(float(np.mean([p["psnr_db"] for p in per_light])), 2),
              "per_light": per_light, "design_condition": round(cond, 2)}
    return q, scale, bias, exposure, errors


# ----------------------------------------------------------------------------------------------
# the job


def export_job(scene, obj, settings: ExportSettings, out_dir: str, force: bool = False):
    """Export ``obj``'s latest texture bake (a job: yields Progress, returns ExportOutput): a
    transport bake serves every format, a lobes bake the RTI ones.

    Refuses (BakeInputError) before any work when an output exists and ``force`` is False;
    every file is written to a temporary name and renamed when complete."""
    from ..base.blend_files import bake_file, object_bakes
    from .texture_transport import KIND as TT_KIND
    from .texture_transport import load_bake

    settings.validate()
    started = time.perf_counter()
    names = output_names(obj.name, settings)
    if not force:
        for n in names:
            if os.path.exists(os.path.join(out_dir, n)):
                raise BakeInputError(f"{os.path.join(out_dir, n)} exists; use --force to "
                                     "replace it")
    kinds = [b.get("kind") for b in object_bakes(obj)]
    lobes = "transport_texture" not in kinds and "steerable_texture" in kinds
    try:
        if lobes:
            if settings.kind == "":
                raise BakeInputError(f"{obj.name}'s bake is a lobes bake; {settings.format} "
                                     "needs the visibility of a transport bake "
                                     "(bake-textures --method transport)")
            from .steerable_bake import load_texture

            source = lobes_source(load_texture(obj))
            report = {"report": bake_file(obj, "steerable_texture", "steerable texture")}
        else:
            bake, store, report = load_bake(bake_file(obj, TT_KIND, "transport texture"))
            kernel = report["settings"].get("kernel", "linear")
            source = transport_source(bake, store, kernel)
    except (FileNotFoundError, ValueError, KeyError) as exc:
        raise BakeInputError(str(exc)) from None
    R, S = source.resolution, source.lights.size
    yield Progress(0, 3, f"{obj.name}: {settings.format} from {S} directions at {R}x{R}")
    base = os.path.join(out_dir, output_stem(obj.name, settings))
    files, figures = {}, {}
    seconds = {}
    if settings.format in ("sh-l1", "monosh"):
        t0 = time.perf_counter()
        normals = texel_normals(scene, obj, R, settings.normal_samples)
        seconds["normal_bake"] = time.perf_counter() - t0
        yield Progress(1, 3, f"{obj.name}: projecting onto L1 spherical harmonics")
        t0 = time.perf_counter()
        weights = light_weights(settings, store.directions, kernel)
        indirect = _indirect_over_pi(bake, store, settings)
        L, errors, covered = sh_export(store.array, store.directions, weights, normals,
                                       indirect)
        seconds["fit"] = time.perf_counter() - t0
        rot = object_rotation(obj)
        layers = godot_layers(L, rot)
        meta = {"format": f"relightable_textures.{settings.format}", "object": obj.name,
                **DECODE[settings.format]}
        if settings.format == "sh-l1":
            for key, img in layers.items():
                path = f"{base}_{key}.exr"
                exrio.write_exr(path, {c: img[:, i].reshape(R, R) for i, c in enumerate("RGB")},
                                {**meta, "layer": key}, pixel_type="half")
                files[key] = path
            err = errors["sh_half"]
            bytes_per_texel = 4 * 3 * 2
        else:
            L0m, dm = sh.to_monosh(L)
            v = np.einsum("ji,pj->pi", rot, 2.0 * dm - 1.0)                 # object frame
            d8 = np.rint(np.clip((v @ BLENDER_TO_UNITY.T) * 0.5 + 0.5, 0, 1) * 255)
            exrio.write_exr(f"{base}_L0.exr", {c: L0m[:, i].reshape(R, R)
                                               for i, c in enumerate("RGB")},
                            {**meta, "layer": "L0 (ready to apply: E/pi = L0 + n . L1)"},
                            pixel_type="half")
            write_png(f"{base}_L1.png", d8.astype(np.uint8).reshape(R, R, 3)[::-1])
            files.update(L0=f"{base}_L0.exr", L1=f"{base}_L1.png")
            err = errors["monosh"]
            bytes_per_texel = 3 * 2 + 3
        figures = {"error_vs_our_relight": err, "errors_all": errors,
                   "error_measure": "relative RMS irradiance over covered texels at normals "
                                    "tilted 0/15/30/45 deg (8 azimuths) from the baked normal, "
                                    "vs the transport's own irradiance at that normal",
                   "covered_texels": covered, "bytes_per_texel": bytes_per_texel,
                   "lighting": ({"env": os.path.abspath(settings.env), "rotate": settings.rotate}
                                if settings.env else {"sun": list(settings.sun),
                                                      "sun_angle": settings.sun_angle}),
                   "indirect": ("uniform over the texel's hemisphere (from the bake's bounce "
                                "term)" if indirect is not None else
                                "not included" + (" (environment lighting: the bake's bounce "
                                                  "term is per sun)" if settings.env else
                                                  " (the bake has none)"))}
    else:
        t0 = time.perf_counter()
        gen = rti_export(source, settings, progress_every=max(1, S // 20))
        while True:
            try:
                step = next(gen)
            except StopIteration as stop:
                q, scale, bias, exposure, errors = stop.value
                break
            yield Progress(1, 3, step.message)
        seconds["fit"] = time.perf_counter() - t0
        yield Progress(2, 3, f"{obj.name}: writing planes and the web page")
        folder = rti_files.write(base, q.reshape(R, R, *q.shape[1:]), scale, bias,
                                 settings.kind, exposure=exposure,
                                 title=f"{obj.name} ({settings.format}, relightable)")
        files["folder"] = folder
        K = q.shape[1]
        figures = {"error_vs_our_relight": errors, "terms": K, "bytes_per_texel": 3 * K,
                   "exposure": exposure, "fitted_from": source.what,
                   "error_measure": "RMSE / PSNR of sRGB display values in [0, 1] at held-out "
                                    "sun directions vs our relight of the same bake (a "
                                    "transport bake: from T, with its bounce term)"}
    seconds["wall_total"] = time.perf_counter() - started
    rep = {"kind": KIND, "object": obj.name, "format": settings.format,
           "settings": asdict(settings), "source": report.get("report"),
           "directions": S, "resolution": R, "files": files, **figures,
           "device": cycles_device.current().report(),
           "timings": {k: round(v, 3) for k, v in seconds.items()}}
    atomic.write_json(base + ".json", rep, default=float)
    files["report"] = base + ".json"
    yield Progress(3, 3, f"{obj.name}: {settings.format} written")
    return ExportOutput(rep, files)
