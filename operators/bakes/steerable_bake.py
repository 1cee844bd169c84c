"""Bake steerable illumination textures with Cycles (bpy).

:func:`bake_steerable_texture` is a generator: it yields :class:`Progress` after every Cycles
bake and *returns* a :class:`BakeResult`. The modal operator, the CLI and the tests all drive
the same generator (:func:`run`), so progress and cancel behave the same everywhere: stopping
iteration (``generator.close()``) leaves the scene exactly as it was, and nothing is written
until :func:`write_bake` runs on a finished result.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field

import bpy
import numpy as np

from ... import __version__
from ...lt_addon.io.transaction import after_commit
from ...lt_addon.io.versions import REPORT_VERSION
from ...lt_addon.io import atomic
from ...lt_addon.io.names import object_stem
from ...lt_addon import caveats
from ...lt_addon.caveats import uv_overlap
from ...lt_addon.settings import check_ranges, setting
from ...lt_addon.steerable.sampled_basis import build_sampled_basis
from ...lt_addon.steerable.basis import paper_basis
from ...lt_addon.steerable.texture import FRAMES, STORAGE_MODES, SteerableTexture
from ..base import cycles_device
from ..base.meshes import bake_uv_name
from ..base.jobs import Progress, run  # noqa: F401  (the bake's job primitives)
from ..base.cycles_bake import (BAKE_MODES, WORLD_SAMPLING, BakeInputError, check_bakeable,
                                check_memory)

BAKE_KIND = "steerable_texture"
#: Fraction of covered texels with overlapping UVs above which a bake warns.
UV_OVERLAP_WARNING = caveats.UV_OVERLAP_WARNING


@dataclass
class TextureBakeSettings:
    """What to bake. Defaults follow the paper (N1 = 7, outgoing radiance)."""

    order: int = setting(7, lo=2, hi=12, help="Basis order N1: N = N1^2 Cycles bakes")
    resolution: int = setting(512, lo=1, hi=16384, help="Texture side in texels")
    samples: int = setting(64, lo=1, hi=65536, help="Cycles samples per texel per bake")
    bounces: int = setting(4, lo=0, hi=64, help="Diffuse bounces (0 = direct light only)")
    frame: str = setting("world", choices=(
        ("world", "World", "Relight the object by a distant light over the world's upper "
                           "hemisphere"),
        ("tangent", "Tangent", "A tileable patch relit per pixel in a surface's UV tangent "
                               "frame")), help="The frame the light directions are in")
    mode: str = setting("radiance", label="Bake", choices=(
        ("radiance", "Radiance", "Albedo x light with interreflection (the paper)"),
        ("irradiance", "Light only", "Light without the albedo, so the albedo stays editable")),
        help="What the bake holds")
    storage: str = setting("half", choices=tuple((m, m, "") for m in STORAGE_MODES),
                           help="EXR precision (u8: 8-bit + min/max)")
    calibration: str = "steerable_cos"
    env_height: int = 128
    seed: int = setting(0, lo=0, help="Cycles seed")
    world_sampling: str = setting("importance", label="World Sampling", choices=(
        ("importance", "Importance", "Lower noise at equal samples"),
        ("none", "None", "BSDF sampling only: exactly linear in the light")),
        help="How Cycles samples the steered world light")

    def validate(self) -> None:
        if not 2 <= self.order <= 12:
            raise BakeInputError(f"order must be in 2..12, got {self.order}")
        if not 1 <= self.resolution <= 16384:
            raise BakeInputError(f"resolution must be in 1..16384, got {self.resolution}")
        if self.samples < 1:
            raise BakeInputError(f"samples must be >= 1, got {self.samples}")
        if not 0 <= self.bounces <= 64:
            raise BakeInputError(f"bounces must be in 0..64, got {self.bounces}")
        if self.frame not in FRAMES:
            raise BakeInputError(f"frame must be one of {FRAMES}, got {self.frame!r}")
        if self.mode not in BAKE_MODES:
            raise BakeInputError(f"mode must be one of {BAKE_MODES}, got {self.mode!r}")
        if self.storage not in STORAGE_MODES:
            raise BakeInputError(f"storage must be one of {STORAGE_MODES}, got {self.storage!r}")
        if self.world_sampling not in WORLD_SAMPLING:
            raise BakeInputError(f"world_sampling must be one of {WORLD_SAMPLING}, "
                                 f"got {self.world_sampling!r}")
        if not 8 <= self.env_height <= 4096:
            raise BakeInputError(f"env_height must be in 8..4096, got {self.env_height}")
        # basis images are float32 (N, R, R, 3) plus the sampled stack of the same size
        check_ranges(self)
        check_memory(2 * self.order ** 2 * self.resolution ** 2 * 3 * 4,
                     f"order {self.order} at {self.resolution}^2",
                     "lower the resolution or the order")


@dataclass
class BakeResult:
    texture: SteerableTexture
    cycles_seconds: float
    total_seconds: float
    bake_calls: int
    condition_number: float
    figures: dict = field(default_factory=dict)


def bake_steerable_texture(scene, obj, settings: TextureBakeSettings, cache=None,
                           client=None, blend_path: str | None = None):
    """Generator: bake ``obj`` under the K sampled steerable lights; returns a BakeResult.

    Each light is a chunk (:mod:`.light_chunks`): with a chunk ``cache``
    (:func:`lobes_chunk_cache`) a rerun reuses the lights a cancelled bake finished, and a
    Dask ``client`` bakes the missing ones on its workers from the saved ``blend_path``; the
    result is the same bit for bit. ``figures["chunks"]`` has the chunk figures.

    Yields
    ------
    Progress
        After every Cycles bake (``total = K + 1``; the last step is the basis solve).
    """
    settings.validate()
    check_bakeable(obj)
    start = time.perf_counter()
    from ...lt_addon.geometry.uv_layout import uv_overlap_report
    from ..base.meshes import uv_triangles

    uv_tris = uv_triangles(obj)
    uv_report = uv_overlap_report(uv_tris, min(settings.resolution, 256))
    e1, e2 = uv_tris[:, 1] - uv_tris[:, 0], uv_tris[:, 2] - uv_tris[:, 0]
    # every UV triangle of zero area: no texel can belong to a face. Blender 5.3's Cycles still
    # writes one texel plus its margin for such a face, 5.0's nothing; the bake keeps nothing.
    no_uv_area = not np.any(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    overlap = uv_overlap(obj.name, uv_report)   # (the report's warning too: lobes_job)
    if overlap:
        yield Progress(0, 1, f"warning: {overlap}")
    basis = paper_basis(settings.order)
    sampled = build_sampled_basis(basis)
    k_total = sampled.n_lights
    r = settings.resolution
    h = settings.env_height
    from .light_chunks import light_stacks

    (stack,), chunks = yield from light_stacks(scene, [obj], lobes_spec(settings), cache,
                                               client if cache is not None else None,
                                               blend_path, 0, k_total + 1, "Cycles bake")
    cycles_seconds, calls = chunks["cycles_seconds"], chunks["calls"]
    if no_uv_area:
        stack[:] = 0.0
    basis_images = sampled.to_basis_images(stack, dtype=np.float32)
    total = time.perf_counter() - start
    record = {
        "resolution": r, "samples": settings.samples, "seed": settings.seed,
        "bounces": settings.bounces, "mode": settings.mode, "env_height": h,
        "world_sampling": settings.world_sampling,
        "object": obj.name, "addon_version": __version__,
        "blender_version": bpy.app.version_string,
    }
    texture = SteerableTexture(basis_images, settings.order, basis.width, sampled.centres,
                               frame=settings.frame, calibration=settings.calibration,
                               settings=record)
    yield Progress(k_total + 1, k_total + 1, "basis solve done")
    return BakeResult(texture, cycles_seconds, total, calls, float(sampled.condition_number),
                      figures={"uv_layout": uv_report, "chunks": chunks})


def lobes_spec(settings: TextureBakeSettings) -> dict:
    """The lobes bake's basis lights (:func:`.light_chunks.light_spec`)."""
    from .light_chunks import light_spec

    return light_spec(settings.order, settings.env_height, settings.resolution,
                      settings.samples, settings.bounces, settings.mode, settings.seed,
                      settings.world_sampling)


def lobes_chunk_cache(scene, obj, settings: TextureBakeSettings, out_dir: str):
    """The chunk cache of a lobes bake of ``obj`` into ``out_dir``:
    ``<out_dir>/.relight_cache/<object>_lobes/`` (:func:`.light_chunks.light_cache`)."""
    from .light_chunks import light_cache
    from ..base.bake_inputs import cache_root

    return light_cache(scene, [obj], lobes_spec(settings),
                       os.path.join(cache_root(out_dir), object_stem(obj.name) + "_lobes"))


def default_output_dir(blend_path: str) -> str:
    """``<blend folder>/<blend stem>_relight`` (or a temp-safe name for unsaved files)."""
    if blend_path:
        folder, base = os.path.split(os.path.abspath(blend_path))
        return os.path.join(folder, os.path.splitext(base)[0] + "_relight")
    return os.path.abspath("relight_output")


def write_bake(result: BakeResult, obj, out_dir: str, settings: TextureBakeSettings,
               write_json: bool = True) -> dict:
    """Write the EXR (and, with ``write_json``, the JSON report) atomically and record the bake
    on ``obj``.

    Returns the report dict. The EXR goes to ``<out_dir>/<object>_steerable.exr`` and the
    report next to it as ``.json``; both replace earlier files only once complete.
    """
    os.makedirs(out_dir, exist_ok=True)
    safe = object_stem(obj.name)
    exr_path = os.path.join(out_dir, f"{safe}_steerable.exr")
    json_path = os.path.join(out_dir, f"{safe}_steerable.json")
    t0 = time.perf_counter()
    storage = settings.storage
    nbytes = result.texture.save(exr_path, storage)
    write_seconds = time.perf_counter() - t0
    tex = result.texture
    n, r = tex.basis_images.shape[0], tex.resolution
    report = {
        "kind": BAKE_KIND,
        "object": obj.name,
        "uv_map": bake_uv_name(obj),   # the map the bake wrote into (the preview reads it)
        "exr": os.path.abspath(exr_path),
        "settings": asdict(settings),
        "condition_number": result.condition_number,
        "device": cycles_device.current().report(),
        "timings": {
            "cycles_bake_seconds": round(result.cycles_seconds, 4),
            "own_work_seconds": round(result.total_seconds - result.cycles_seconds, 4),
            "write_seconds": round(write_seconds, 4),
            "total_seconds": round(result.total_seconds + write_seconds, 4),
            "overhead_fraction": round(
                (result.total_seconds - result.cycles_seconds) / max(result.total_seconds, 1e-9), 4),
            "bake_calls": result.bake_calls,
        },
        "bytes": {
            "exr_file": nbytes,
            "in_memory_float32": int(n * r * r * 3 * 4),
            "per_texel_storage": {"float": n * 3 * 4, "half": n * 3 * 2, "u8": n * 3}[storage],
        },
        "preview_cost": {"basis_images": n, "multiply_adds_per_texel": n * 3},
        **{k: v for k, v in result.figures.items() if k != "chunks"},
    }
    chunks = result.figures.get("chunks")
    if chunks:   # each basis light is a chunk (light_chunks)
        report.update({k: chunks[k] for k in ("chunks_total", "chunks_reused", "distributed")
                       if k in chunks})
    if write_json:
        atomic.write_json(json_path, {**report, "format_version": REPORT_VERSION})
    record_bake(obj, exr_path, report)
    return report


def record_bake(obj, exr_path: str, report: dict) -> None:
    """Replace the object's steerable-texture bake record."""
    from ..base.blend_files import record_kind

    record_kind(obj, BAKE_KIND, exr_path, {
        "order": report["settings"]["order"],
        "resolution": report["settings"]["resolution"],
        "samples": report["settings"]["samples"],
        "storage": report["settings"]["storage"],
        "frame": report["settings"]["frame"],
        "bytes": report["bytes"]["exr_file"],
        "bake_seconds": report["timings"]["total_seconds"],
    })


def truth_directions(texture, count: int = 5) -> list:
    """``count`` light directions for ground truth: elevations spread over 5..85 degrees
    (both ends included), azimuths spread by the golden angle, none within 0.05 (disk units)
    of a baked sample centre, so the relight really interpolates.

    Returns
    -------
    list of ndarray, shape (3,)
    """
    from ...lt_addon.sphere.hemisphere import direction_from_az_el, hemisphere_to_disk

    elevations = np.linspace(5.0, 85.0, max(count, 2))[:count] if count > 1 else np.array([45.0])
    out = []
    for i, el in enumerate(elevations):
        az = (17.0 + 137.508 * i) % 360.0
        for _ in range(36):
            d = direction_from_az_el(az, el)
            gap = np.min(np.hypot(*(texture.centres - hemisphere_to_disk(d)).T))
            if gap > 0.05:
                break
            az += 10.0
        out.append(d)
    return out


def ground_truth_job(scene, obj, texture, settings: TextureBakeSettings, count: int,
                     sheet_path: str | None = None):
    """Job: Cycles ground truth for ``count`` directions (see :mod:`.steerable_truth`), with
    the headline error; returns the JSON-safe figures. With ``sheet_path`` a PNG contact sheet
    of the first four directions is written there."""
    from .steerable_truth import contact_sheet, ground_truth

    result = yield from ground_truth(scene, obj, texture, truth_directions(texture, count),
                                     settings.samples, settings.bounces, settings.mode,
                                     settings.env_height, seed=settings.seed,
                                     world_sampling=settings.world_sampling)
    if sheet_path:
        result["contact_sheet"] = contact_sheet(result["directions"], sheet_path)
    for row in result["directions"]:
        row.pop("images")
    result.update(headline(result, settings))
    return result


@dataclass
class LobesBakeOutput:
    """What :func:`lobes_job` produced: the JSON-safe report (as written next to the EXR) and
    the steerable texture itself -- an object, not a report entry."""
    report: dict
    texture: SteerableTexture


def lobes_job(scene, obj, settings: TextureBakeSettings, out_dir: str, *, truth: int = 0,
              sheet_path: str | None = None, preview: bool = True, sun=None,
              compare: bool = True, resume: bool = True, client=None,
              blend_path: str | None = None):
    """The whole ``bake-textures --method lobes`` verb as one job (a generator of
    :class:`.jobs.Progress`): the steerable bake, ``truth`` held-out Cycles truths (with their
    headline error; a labelled UV-space contact sheet at ``sheet_path``), the EXR, report and
    bake record, the preview and -- with ``truth``, ``preview`` and ``compare`` and a scene
    camera -- ``<object>_steerable_compare.png``: the preview next to a Cycles Sun render from
    the camera at the lowest held-out light. Nothing is written before the bakes are done, so
    cancelling keeps the previous bake; the report is written once, ``timings.wall_total``
    covering all of it. With ``resume`` the finished basis-light bakes are kept in
    ``<out_dir>/.relight_cache/<object>_lobes/`` until the files are written; a Dask ``client``
    bakes the missing ones on its workers from ``blend_path``. Returns a
    :class:`LobesBakeOutput`."""
    from ..preview.preview_nodes import install_preview

    started = time.perf_counter()
    settings.validate()
    if client is not None and (not resume or not blend_path):
        raise BakeInputError("a distributed bake needs the chunk cache (no --no-resume) and a "
                             "saved .blend the workers can open")
    cache = lobes_chunk_cache(scene, obj, settings, out_dir) if resume else None
    result = yield from bake_steerable_texture(scene, obj, settings, cache, client, blend_path)
    truth_seconds = 0.0
    if truth:
        t0 = time.perf_counter()
        gen = ground_truth_job(scene, obj, result.texture, settings, truth, sheet_path)
        result.figures["ground_truth"] = yield from gen
        truth_seconds = time.perf_counter() - t0
    report = write_bake(result, obj, out_dir, settings, write_json=False)
    if preview:
        install_preview(scene, obj, report["exr"], result.texture, sun=sun)
    report["timings"]["truth_seconds"] = round(truth_seconds, 4)
    if truth and preview and compare:
        from ..preview.compare_render import report_comparison

        gt = report["ground_truth"]
        yield Progress(1, 1, "rendering the comparison from the scene camera")
        report["comparison"] = report_comparison(
            scene, [obj], [(r["azimuth"], r["elevation"]) for r in gt["directions"]],
            gt["sun_angle_deg"], os.path.splitext(report["exr"])[0] + "_compare.png",
            4 * settings.samples)
        report["timings"]["compare_seconds"] = report["comparison"].get("seconds", 0.0)
    if cache is not None:   # once the bake is committed the chunks have served
        after_commit(out_dir, cache.clear)
    report["timings"]["wall_total"] = round(time.perf_counter() - started, 4)
    report["warnings"] = caveats.report_warnings(report)   # said by the CLI and the panel
    atomic.write_json(os.path.splitext(report["exr"])[0] + ".json",
                      {**report, "format_version": REPORT_VERSION})
    return LobesBakeOutput(report, result.texture)


def headline(truth: dict, settings: TextureBakeSettings) -> dict:
    """One figure for "how good is my bake": the relative RMSE against Cycles Sun lamps (the
    light users relight with), combined over the held-out lights as ``sqrt(mean(rel^2))`` --
    as the transport method's report -- with what it means in words. Falls back to the same
    steered light when no Sun truth was baked."""
    rows = truth["directions"]
    key = "sun" if rows and all("sun" in r["errors"] for r in rows) else "same_light"
    rel = np.array([r["errors"][key]["rel_fro"] for r in rows], np.float64)
    if not rel.size:
        return {}
    what = (f"Cycles Sun lamp of {truth['sun_angle_deg']:.0f} deg (the steered lobe's width), "
            if key == "sun" else "Cycles bake of the same steered light, ")
    return {"headline_rel_rmse": float(np.sqrt(np.mean(rel ** 2))), "headline_of": key,
            "headline_meaning": f"relative RMSE of the relit texture vs a {what}"
                                f"{settings.samples} spp, {settings.bounces} bounces, over "
                                f"{rel.size} held-out light directions (0 = identical)"}


def load_texture(obj) -> SteerableTexture:
    """The steerable texture recorded on ``obj`` (its EXR path resolved against the .blend)."""
    from ..base.blend_files import bake_file

    return SteerableTexture.load(bake_file(obj, BAKE_KIND, "steerable texture"))
