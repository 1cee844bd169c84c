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

from ...lt_addon.export import godot, rti_files
# Formats, settings and fitting are bpy-free (lt_addon/export/fitting.py), re-exported here.
from ...lt_addon.export.fitting import (BLENDER_TO_UNITY, DECODE, FORMATS, LIGHTMAPS,  # noqa: F401
                                        TILTS, ExportSettings, RadianceSource, godot_layers,
                                        held_out_lights, indirect_over_pi, light_weights,
                                        lobes_source, output_names, output_stem,
                                        radiance_at, read_environment, rti_export, sh_export,
                                        transport_source)
from ...lt_addon.export import sh_lightmap as sh
from ...lt_addon.io import atomic, exrio
from ...lt_addon.io.contact_sheet import write_png
from ..base import cycles_device
from ..base.cycles_bake import BakeInputError
from ..base.jobs import Progress

KIND = "export"


@dataclass
class ExportOutput:
    """A finished export: its report (also written as ``<object>_<format>.json``) and files."""
    report: dict
    files: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------------------------
# inputs


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


# ----------------------------------------------------------------------------------------------
# SH lightmaps


# ----------------------------------------------------------------------------------------------
# RTI


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
    if not force:   # (out_dir may be the staging folder of the export's transaction)
        from ...lt_addon.io.transaction import target_of

        for n in names:
            if os.path.exists(os.path.join(target_of(out_dir), n)):
                raise BakeInputError(f"{os.path.join(target_of(out_dir), n)} exists; use "
                                     "--force to replace it")
    kinds = [b.get("kind") for b in object_bakes(obj)]
    lobes = "transport_texture" not in kinds and "steerable_texture" in kinds
    try:
        if lobes:
            if settings.kind == "":
                raise BakeInputError(f"{obj.name}'s bake is a lobes bake; {settings.format} "
                                     "needs the visibility of a transport bake "
                                     "(bake-textures --method transport)")
            from .steerable_bake import load_texture

            if settings.format == "sun-indirect":
                raise BakeInputError(f"{obj.name}'s bake is a lobes bake; sun-indirect needs "
                                     "a transport bake's bounce term")
            source = lobes_source(load_texture(obj))
            report = {"report": bake_file(obj, "steerable_texture", "steerable texture")}
        else:
            bake, store, report = load_bake(bake_file(obj, TT_KIND, "transport texture"))
            store.array     # T's values checked (finite, in [0, 1/pi]) before any work
            kernel = report["settings"].get("kernel", "linear")
            source = transport_source(bake, store, kernel)
    except (FileNotFoundError, ValueError, KeyError) as exc:
        raise BakeInputError(str(exc)) from None
    if settings.format == "sun-indirect":
        return (yield from _sun_indirect(obj, settings, out_dir, bake, report, started))
    R, S = source.resolution, source.lights.size
    yield Progress(0, 3, f"{obj.name}: {settings.format} from {S} directions at {R}x{R}")
    base = os.path.join(out_dir, output_stem(obj.name, settings))
    files, figures = {}, {}
    seconds = {}
    if settings.format in LIGHTMAPS:
        t0 = time.perf_counter()
        normals = texel_normals(scene, obj, R, settings.normal_samples)
        seconds["normal_bake"] = time.perf_counter() - t0
        yield Progress(1, 3, f"{obj.name}: projecting onto L1 spherical harmonics")
        t0 = time.perf_counter()
        weights = light_weights(settings, store.directions, kernel)
        indirect = indirect_over_pi(bake, store, settings, kernel)
        variants = {}
        if settings.format == "godot-lightmap":
            ver = settings.godot
            variants[f"godot_{ver}"] = lambda Lc: godot.decoded_sh(
                godot.encode(Lc, ver).astype(np.float16).astype(np.float64), ver)
        L, errors, covered = sh_export(store.array, store.directions, weights, normals,
                                       indirect, variants)
        seconds["fit"] = time.perf_counter() - t0
        meta = {"format": f"relightable_textures.{settings.format}", "object": obj.name,
                **{k: (v if isinstance(v, str) else v[settings.godot])
                   for k, v in DECODE[settings.format].items()}}
        if settings.format == "sh-l1":
            for key, img in godot_layers(L).items():
                path = f"{base}_{key}.exr"
                exrio.write_exr(path, {c: img[:, i].reshape(R, R) for i, c in enumerate("RGB")},
                                {**meta, "layer": key}, pixel_type="half")
                files[key] = path
            err = errors["sh_half"]
            bytes_per_texel = 4 * 3 * 2
        elif settings.format == "godot-lightmap":
            yield Progress(2, 3, f"{obj.name}: writing the Godot {settings.godot} folder")
            import tempfile

            from ..base.gltf import write_glb
            with tempfile.TemporaryDirectory(prefix="relight-gltf-") as tmp:
                glb = os.path.join(tmp, "object.glb")
                gltf_info = write_glb(scene, obj, glb, uv_map=report.get("uv_map"))
                files.update(godot.write(base, L, R, settings.godot, gltf_info["node"], glb,
                                         meta))
            err = errors[f"godot_{settings.godot}"]
            bytes_per_texel = 4 * 3 * 2
        else:
            L0m, dm = sh.to_monosh(L)
            v = 2.0 * dm - 1.0                                               # world frame
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
                   "frame": DECODE[settings.format]["axes"],
                   "lighting": ({"env": os.path.abspath(settings.env), "rotate": settings.rotate}
                                if settings.env else {"sun": list(settings.sun),
                                                      "sun_angle": settings.sun_angle}),
                   "indirect": ("uniform over the texel's hemisphere (from the bake's bounce "
                                "term)" if indirect is not None else
                                "not included" + (" (environment lighting: the bake's bounce "
                                                  "term is per sun)" if settings.env else
                                                  " (the bake has none)"))}
        if settings.format == "godot-lightmap":
            figures["godot"] = {"version": settings.godot, "gltf": gltf_info,
                                "exposure_normalization": 1.0}
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


def _sun_indirect(obj, settings, out_dir, bake, report, started):
    """The sun-indirect export (see :mod:`...lt_addon.export.sun_indirect`)."""
    from ...lt_addon.export import sun_indirect

    if bake.indirect is None:
        raise BakeInputError(f"{obj.name}'s bake has no bounce term (it was baked with "
                             "--bounces 0); sun-indirect exports the bounce light")
    Ri = int(bake.indirect.resolution)
    yield Progress(1, 3, f"{obj.name}: sampling the bounce light at "
                         f"{sun_indirect.GRID[0] * sun_indirect.GRID[1]} sun directions "
                         f"({Ri}x{Ri})")
    t0 = time.perf_counter()
    basis, table, figures = sun_indirect.fit(lambda d: bake.indirect.relight(d),
                                             held_out_lights(settings.held_out),
                                             settings.components)
    fit_s = time.perf_counter() - t0
    yield Progress(2, 3, f"{obj.name}: writing {figures['components']} basis lightmaps")
    base = os.path.join(out_dir, output_stem(obj.name, settings))
    meta = {"format": "relightable_textures.sun-indirect", "object": obj.name,
            "frame": "UV2 = the bake's UV map; sun az/el in Blender's world frame (Godot: "
                     "(x, y, z) = Blender (x, z, -y))"}
    files = sun_indirect.write(base, basis, table, figures, meta)
    rep = {"kind": KIND, "object": obj.name, "format": settings.format,
           "settings": asdict(settings), "source": report.get("report"),
           "resolution": Ri, "files": files, **figures,
           "bytes_per_texel": 3 * 2 * figures["components"],
           "error_measure": "relative RMS radiance over all texels at held-out sun "
                            "directions (above 10 deg), the bilinear table vs the bake's own "
                            "bounce term",
           "timings": {"fit": round(fit_s, 3),
                       "wall_total": round(time.perf_counter() - started, 3)}}
    atomic.write_json(base + ".json", rep, default=float)
    files["report"] = base + ".json"
    yield Progress(3, 3, f"{obj.name}: sun-indirect written")
    return ExportOutput(rep, files)
