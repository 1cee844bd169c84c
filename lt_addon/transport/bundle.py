"""A transport-texture bake on disk, without Blender: its settings, what it holds, the files and
report it is written as, reading it back and relighting it (NumPy).

The bundle of one object, in the bake's output folder (``<name>`` its object's safe name):
``<name>_transport_texture.npy`` with its ``.json`` header (:class:`.texture.TransportStore`,
T as float16, S x R x R),
``<name>_albedo.exr``, the indirect term when the scene bounces (``<name>_indirect.npz``:
gathered by rays, :mod:`.gathered_texture`; or ``<name>_indirect.exr``: a steerable texture),
the fitted model (``_transport_model.npz`` or ``_transport_steerable.exr``) and
``<name>_texture_report.json``: ``kind`` :data:`KIND`, ``format`` :data:`FORMAT`, the settings,
file paths, bytes, timings and the error figures. :func:`load_bake` reads it from plain Python::

    bake, store, report = load_bake("out/bumps_relight/Bumps_texture_report.json")
    rgb = relight(bake, store, direction=(0.3, 0.2, 0.93), sun_angle=2.0)   # (R, R, 3)

The bpy layer (``operators/bakes/texture_transport.py``) bakes T with Cycles and records the
bake on its object; everything here is NumPy.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ..errors import InputError
from .. import faults
from ..io.names import object_stem
from ..io import atomic, exrio, untrusted, versions
from ..settings import check_ranges, setting
from ..sphere.hemisphere import direction_from_az_el
from . import texture as tt
from .horizon_map import PATH_AZIMUTHS, STRIPS
from .gathered_texture import GatheredIndirect, direction_matrix, indirect_images

KIND = "transport_texture"
#: The bundle's format (the report's ``format``): readers refuse a newer one with one line.
#: 1: reports written before the field existed read as 1.
FORMAT = 1


MODELS = ("pca", "blocks", "steerable", "none")


#: What the viewport shows (``auto``: T itself when its atlas fits, else the PCA; see
#: :func:`..lt_addon.transport.sparse_tables.choose_viewport`).
VIEWPORTS = ("auto", "horizon", "transport", "blocks", "pca")


INDIRECT = ("gather", "steerable", "none")
#: Directions along an animated Sun's path: added when the scene's Sun moves (auto), or not.
SUN_PATH = ("auto", "off")
#: The suffix of a --directions spec that asks for them: ``hemi:1600:1.5+sun-path[:STEP_DEG]``.
SUN_PATH_SUFFIX = "+sun-path"


def split_sun_path(spec: str):
    """``(base spec, step in degrees or None)`` of a --directions spec with an optional
    ``+sun-path[:STEP]`` suffix (None: no suffix; the step defaults to 0.5)."""
    text = str(spec).strip()
    base, sep, rest = text.lower().partition(SUN_PATH_SUFFIX)
    if not sep:
        return text, None
    rest = rest.strip()
    if rest and not rest.startswith(":"):
        raise InputError(f"bad direction spec {spec!r}: expected '...+sun-path' or "
                         "'...+sun-path:STEP' (degrees between path directions)")
    try:
        step = float(rest[1:]) if rest else 0.5
    except ValueError:
        raise InputError(f"bad direction spec {spec!r}: the sun-path step must be a number of "
                         "degrees, e.g. 'hemi:1600:1.5+sun-path:0.5'") from None
    if not 0.05 <= step <= 10.0:
        raise InputError(f"the sun-path step must be in 0.05..10 degrees, got {step:g}")
    return text[:len(base)], step


#: How the direct transport is baked: rays where the scene allows (auto), rays or refuse, Cycles calls.
DIRECT = ("auto", "rays", "cycles")


#: Held-out truth lights (azimuth, elevation in degrees): the four elevations of issue 13.
TRUTH_LIGHTS = ((37.0, 10.0), (161.0, 30.0), (283.0, 55.0), (59.0, 80.0))


@dataclass
class TransportTextureSettings:
    """What to bake (``directions``, ``resolution``, indirect effort) and which model to fit.

    ``bounces``: the scene's diffuse bounces for the indirect term (0 = direct light only).
    ``tol``: relative Frobenius residual of T the PCA models keep (or ``components``: a fixed
    count for ``pca``). ``sun_angle``: the sun size (degrees) the viewport tables are made
    for (the NumPy relight takes any size). ``viewport``: what the live preview shows --
    ``transport`` relights from T itself (a few baked directions per pixel through sparse
    kernel tables), ``blocks`` from a PCA per texel block (:mod:`.block_viewport`), ``pca``
    from the fitted global PCA, ``auto`` T when its preview atlas fits ``gpu_budget`` (MiB),
    else the blocks, or the PCA when it is measured closer to T
    (:func:`..lt_addon.transport.sparse_tables.choose_viewport`, :func:`fit_viewport`).
    """

    directions: str = setting(
        "hemi:400:1.5", metavar="SPEC", panel=False,
        help="sun directions, hemi:N[:P] (N hard-sun bakes over the upper hemisphere, 1 sample "
             "each; P > 1 denser near the horizon), optionally +sun-path[:STEP] (directions STEP "
             "degrees apart along the scene Sun's animated path; 0.5 by default)")
    sun_path: str = setting("auto", label="Sun Path", choices=(
        ("auto", "Auto", "When the scene's Sun is animated (keyframes, drivers, the Sun Position "
         "add-on), add directions along its path, --sun-path-step apart, and find the "
         "horizons at the texture's side"),
        ("off", "Off", "The direction set only")),
        help="Directions along the animated Sun's path")
    sun_path_step: float = setting(
        0.5, lo=0.05, hi=10.0, label="Sun Path Step",
        help="Degrees between the directions added along the Sun's path (0.5 holds a 2-degree "
             "Sun's shadows), the animated Sun's or a study's")
    study: str = setting(
        "", label="Sun Study", metavar="LAT,LON,ZONE,DATE,...",
        help="For a sun study to come (relight sun-study): add the Sun of every hour of these "
             "dates at this place and each date's path, Sun Path Step apart, e.g. "
             "'51.5,-0.13,Europe/London,2026-06-21,2026-12-21' (optional north=DEG, "
             "elevation=M); a date range FIRST..LAST[/N days] bakes the paths of 24 of its "
             "dates spread over their declinations ('...,2026-01-01..2026-12-31'); "
             "'scene,2026-06-21,...' takes the place, zone and north of the scene's Sun "
             "Position add-on; empty: none")
    resolution: int = setting(256, lo=4, hi=8192, soft=(8, 8192), help="Texture side in texels")
    bounces: int = setting(-1, lo=-1, hi=64, help=(
        "Diffuse bounces (0 = direct light only); -1: the scene's own (Render > Light Paths: "
        "Diffuse, capped by Total), as its render has them"))
    texel_sampling: str = setting("footprint", label="Texel Sampling", choices=(
        ("footprint", "Footprint", "Where a shadow edge or a thin triangle passes a texel, "
         "average 16 rays over the texel as a converged Cycles bake does (a brick relief under "
         "a 2-degree sun: 0.07 from Cycles' converged bake, as close as 16 Cycles samples; "
         "one ray is 0.36)"),
        ("centre", "Centre", "One ray per texel, at its centre: a 1-spp Cycles bake's direct "
         "light (normal and bump maps are still sampled over the texel)")),
        help="Where in each texel the direct rays start")
    direct: str = setting("auto", label="Direct Light", choices=(
        ("auto", "Auto", "Ray-traced (Embree) when the scene allows it, else one Cycles call per "
         "direction; the report says which and why"),
        ("rays", "Rays", "Ray-traced direct light; refuse a scene rays cannot reproduce (alpha "
         "shadows, hair, volumes, true displacement)"),
        ("cycles", "Cycles", "One Cycles bake call per direction: the reference path")),
        help="How the direct transport is baked")
    indirect: str = setting("gather", label="Indirect Light", choices=(
        ("gather", "Gathered", "Rays from the indirect grid read T's own directions, 1 to "
         "'bounces' bounces, kept as a PCA over directions: measured closer to Cycles than the "
         "steerable term at every light, in less time"),
        ("steerable", "Steerable", "A low-order steerable bake of Cycles' indirect pass "
         "(order^2 Cycles calls): the earlier default"),
        ("none", "None", "Direct light only")),
        help="How the indirect light (interreflection) is baked")
    # (measured for the balanced bake, 2026-12-04, against 10-degree Cycles Suns at 4 held-out
    # lights, bumps 256^2 / statue + ground 128^2: 32 rays 0.0320 / 0.0377, 64 rays 0.0294 /
    # 0.0321, 128 rays 0.0286 / 0.0296 for 0.6 s more on the statue, 256 rays 0.0283 / 0.0287
    # for 2.1 s more; 8 / 32 components 0.0302 / 0.0290 and 0.0377 / 0.0305; smoothing the
    # images by 0.75 texels helped only at 32 rays or fewer; docs/bench/2026-transport-log.md)
    indirect_rays: int = setting(
        128, lo=4, hi=4096, label="Indirect Rays",
        help="Cosine-weighted rays per point of the indirect grid (gathered indirect light)")
    indirect_components: int = setting(
        16, lo=1, hi=256, label="Indirect Components",
        help="PCA components over directions of the gathered indirect light: at least "
             "this many, up to 4x where the scene's bounce light needs more (an interior lit "
             "through a window)")
    indirect_order: int = 3
    indirect_resolution: int = setting(
        128, lo=4, hi=8192, label="Indirect Resolution",
        help="Texture side of the indirect-light bake (interreflection is smooth: half the "
             "texture's is the cheap choice, the full one the accurate one)")
    indirect_samples: int = setting(
        64, lo=1, hi=65536, label="Indirect Samples",
        help="Samples of the low-order steerable bake of the indirect light")
    indirect_smoothing: float = 0.75
    model: str = setting("pca", label="Model", choices=(
        ("pca", "PCA eigen-textures", "Global PCA of the transport: live viewport preview"),
        ("blocks", "Block PCA", "Clustered PCA over texel blocks (CLI/NumPy relight only)"),
        ("steerable", "Steerable (quadrature)", "The paper's basis fitted noise-free from T"),
        ("none", "None", "Keep T only")), help="What is fitted to T")
    components: int | None = setting(
        None, lo=0, soft=(0, 512), label="Components",
        help="PCA eigen-textures to keep (the presets' measured figures use a fixed count), or "
             "the steerable order; none (0 in the panel) = as many as the tolerance needs")
    tol: float = setting(0.02, lo=1e-6, hi=0.999, soft=(0.001, 0.5), label="PCA Tolerance",
                         help="Relative residual of T the PCA keeps when no component count is "
                              "given (fewer components when larger)")
    block: int = 16
    sun_angle: float = setting(
        -1.0, lo=-1.0, hi=30.0, label="Sun Size", panel=False,
        help="Angular diameter of the preview sun in degrees, for the preview's tables and the "
             "truths (changing it re-tabulates the preview, no re-bake); -1: the scene's Sun's "
             "(Blender's default 0.526), 2 without a Sun")
    under_horizon: float = setting(
        -1.0, lo=-1.0, hi=10.0, label="Under the Horizon", metavar="DEG",
        help="Degrees under the horizon T's directions reach, for the part of a wide sun's "
             "disc there that lights walls and slopes (a 10-degree Sun 3 degrees high reaches "
             "2 under): the band above the horizon mirrored, about a fifth more directions "
             "at 5; -1: the bake Sun's radius, at least 5; 0: none (a floor alone needs none)")
    kernel: str = "linear"
    table_size: int = setting(
        32, lo=8, hi=256, label="Preview Table Size",
        help="Texels across the hemisphere disk of the preview's coefficient tables (64 "
             "follows low suns more closely than 32; 4x the tabulation time); T's and the "
             "gathered indirect light's take at least 64")
    seed: int = setting(0, lo=0, help="Cycles seed")
    viewport: str = setting("auto", label="Viewport", choices=(
        ("auto", "Auto", "Per object: the horizon map where rays baked it and it is measured "
         "closer to rays at held-out suns; else T itself when its atlas fits the GPU budget "
         "(400 directions and their band under the horizon at 256^2: 43 MiB; 1600: 165 "
         "MiB), else a PCA per texel block, or the global PCA when it is measured closer to "
         "T"),
        ("horizon", "Horizons", "Per-texel horizons found by rays: a shadow edge moves with "
         "the sun instead of blending the baked directions' shadows (no ghosting at low suns); "
         "32 lookups per pixel and 4 bytes per texel and azimuth with the edges' spread over "
         "each texel's footprint (22 and 2.7 without, where the spreads would not fit the GPU "
         "budget), 10 and 2 more where a vertical edge (a jamb, a post) lies between two "
         "azimuths, 40 and 4 more where a window's open band and its edges' spread are kept; "
         "needs the ray engine"),
        ("transport", "Transport (T)", "Relight from T itself: a few baked directions per "
         "pixel through sparse kernel tables; keeps cast shadows on large receivers; an atlas "
         "of every direction in memory"),
        ("blocks", "Blocks (CPCA)", "A PCA per square block of texels, block size and "
         "components chosen within the GPU budget: keeps cast shadows at large texture sizes "
         "with few lookups per pixel"),
        ("pca", "PCA", "The fitted PCA's eigen-textures: small, smooths cast shadows on large "
         "receivers")), help="What the live preview shows")
    horizon_azimuths: int = setting(
        128, lo=0, hi=1024, label="Horizon Azimuths",
        help="Azimuths of the horizon map rays bake for the viewport (0: none); 128 are 2.8 "
             "degrees apart")
    horizon_resolution: int = setting(
        0, lo=0, hi=8192, label="Horizon Resolution", metavar="SIDE",
        help="Side of the horizon map (0: the texture's, at most 1024): a shadow edge is as "
             "wide as the sun's penumbra, many texels on a large receiver, so a 2048^2 "
             "texture's horizons at 1024^2 cost a quarter of the rays and GPU memory. When "
             f"the Sun is animated (Sun Path), the texture's side and at least {PATH_AZIMUTHS} "
             "azimuths")
    gpu_budget: int = setting(
        512, lo=8, hi=65536, label="GPU Budget", metavar="MIB",
        help="MiB of GPU memory each object's viewport may take: auto shows T itself when its "
             "atlas fits, and the block viewport chooses its block size and components within it")

    def validate(self):
        """Check ranges; returns the DirectionSet."""
        base, _ = split_sun_path(self.directions)
        try:
            dset = tt.parse_directions(base)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        if self.sun_path not in SUN_PATH:
            raise InputError(f"sun path must be one of {SUN_PATH}, got {self.sun_path!r}")
        if self.study:
            from ..sun.study_directions import parse as parse_study

            parse_study(self.study)
        if dset.size < 8:
            raise InputError(f"need at least 8 upper-hemisphere directions, got {dset.size}")
        if not 4 <= self.resolution <= 8192:
            raise InputError(f"resolution must be in 4..8192, got {self.resolution}")
        if not -1 <= self.bounces <= 64:
            raise InputError(f"bounces must be in 0..64 (-1: the scene's), got {self.bounces}")
        if self.indirect not in INDIRECT:
            raise InputError(f"indirect must be one of {INDIRECT}, got {self.indirect!r}")
        if self.model not in MODELS:
            raise InputError(f"model must be one of {MODELS}, got {self.model!r}")
        if not 4 <= self.indirect_rays <= 4096 or not 1 <= self.indirect_components <= 256:
            raise InputError(f"indirect rays must be in 4..4096 and components in 1..256, got "
                             f"{self.indirect_rays} and {self.indirect_components}")
        if not 2 <= self.indirect_order <= 7:
            raise InputError(f"indirect order must be in 2..7, got {self.indirect_order}")
        if not 4 <= self.indirect_resolution <= 8192 or self.indirect_samples < 1:
            raise InputError("indirect resolution must be in 4..8192 and samples >= 1")
        if not 0.0 <= self.indirect_smoothing <= 16.0:
            raise InputError(f"indirect smoothing must be in 0..16 texels, got "
                                 f"{self.indirect_smoothing}")
        if self.components is not None and self.components < 1:
            raise InputError(f"components must be >= 1, got {self.components}")
        if not 0.0 < self.tol < 1.0:
            raise InputError(f"tol must be in (0, 1), got {self.tol}")
        if self.model == "blocks" and (self.block < 2 or self.resolution % self.block):
            raise InputError(f"block {self.block} must divide the resolution {self.resolution}")
        if not (0.0 <= self.sun_angle <= 30.0 or self.sun_angle == -1.0):
            raise InputError(f"sun angle must be in 0..30 degrees (-1: the scene Sun's), got "
                             f"{self.sun_angle}")
        if not (0.0 <= self.under_horizon <= 10.0 or self.under_horizon == -1.0):
            raise InputError(f"under the horizon must be in 0..10 degrees (-1: the Sun's "
                             f"radius, at least 5), got {self.under_horizon}")
        if self.kernel not in tt.KERNELS:
            raise InputError(f"kernel must be one of {tt.KERNELS}, got {self.kernel!r}")
        if not 8 <= self.table_size <= 256:
            raise InputError(f"table size must be in 8..256, got {self.table_size}")
        if self.direct not in DIRECT:
            raise InputError(f"direct must be one of {DIRECT}, got {self.direct!r}")
        if self.viewport not in VIEWPORTS:
            raise InputError(f"viewport must be one of {VIEWPORTS}, got {self.viewport!r}")
        if self.horizon_azimuths in (1, 2):
            raise InputError(f"horizon azimuths must be 0 (none) or 3 or more, got "
                             f"{self.horizon_azimuths}")
        if self.horizon_resolution and not 4 <= self.horizon_resolution <= 8192:
            raise InputError(f"horizon resolution must be 0 (the texture's, at most 1024) or "
                             f"in 4..8192, got {self.horizon_resolution}")
        check_ranges(self)
        return dset


def direct_summary(direct: dict, directions: int) -> str:
    """One line on how a transport bake's direct light was baked (its report's ``direct``)."""
    if direct.get("engine") == "rays":
        side = (f" at {direct['horizon_resolution']}^2" if direct.get("horizon_resolution")
                else "")
        raised = direct.get("horizons_raised")
        why = (f", raised from {raised['from']['azimuths']} at {raised['from']['side']}^2 for "
               f"the animated Sun" if raised else "")
        fh = direct.get("horizon_footprints") or {}
        fh_text = (f" (footprints of {fh['texels']} texels, {fh['seconds']:.1f} s)"
                   if fh.get("texels") else "")
        hc = direct.get("horizon_crossings") or {}
        if hc.get("vertical"):       # vertical edges placed between two azimuths
            fh_text += (f"; {hc['vertical']} vertical edges between azimuths, {hc['rays']} rays,"
                        f" {hc['seconds']:.1f} s")
        horizons = (f"; horizons at {direct['horizon_azimuths']} azimuths{side}{why}, "
                    f"{direct['horizon_seconds']:.1f} s of it{fh_text}"
                    if direct.get("horizon_azimuths") else "")
        footprint = ""
        if direct.get("texel_sampling") == "footprint" and direct.get("texels"):
            texel_dirs = sum(direct["texels"]) * directions
            refined = sum(direct.get("footprint_refined") or [0])
            footprint = (f"; texel footprints at {100 * refined / max(texel_dirs, 1):.0f} % of "
                         f"texel-directions, {direct.get('footprint_rays', 0) / max(texel_dirs, 1):.2f}"
                         " rays per texel-direction more")
        return (f"Direct light: {directions} directions by rays ({direct.get('library', '')}, "
                f"{direct.get('seconds', 0):.1f} s, "
                f"{direct.get('rays_per_second', 0) / 1e6:.1f} M rays/s{horizons}{footprint})")
    return f"Direct light: {directions} Cycles calls ({direct.get('why', 'asked for')})"


@dataclass
class ObjectBake:
    """What one object's bake produced (arrays in memory are small: no T)."""

    name: str
    store_path: str
    albedo: np.ndarray                      # (R, R, 3) float32
    indirect: object = None                 # GatheredIndirect, SteerableTexture or None
    model: object = None                    # TexturePCA / BlockPCA / SteerableTexture / None
    fit_seconds: float = 0.0
    store: object = None                    # the TransportStore (temporary until written)
    view: object = None                     # the BlockViewport when the viewport shows blocks
    viewport: dict = None                   # what the viewport shows and why (the report's)
    horizon: object = None                  # the HorizonMap when the viewport shows horizons
    found_horizon: object = None            # the HorizonMap the bake found, shown or not


@dataclass
class TransportTextureResult:
    objects: list
    directions: object
    settings: TransportTextureSettings
    seconds: dict = field(default_factory=dict)
    bake_calls: int = 0
    peak_rss_mb: float = 0.0         # anonymous memory above the level before the bake
    growth_after_first_mb: float = 0.0   # ... above the level after the first direction
    peak_by_stage_mb: dict = field(default_factory=dict)   # {albedo, direct, indirect, fit}
    cache: object = None             # the stages' ChunkCaches, inner first (None: resume off)
    chunks: dict = field(default_factory=dict)   # chunks_total, chunks_reused, chunk_directions
    indirect_chunks: dict = None     # the indirect stage's light chunks (light_stacks figures)
    direct: dict = None              # which engine baked the direct term, why, and its figures


#: Texture lookups per pixel of the horizon viewport: both edges at the two azimuths around each
#: of the sun disc's strips (horizon_map.STRIPS, five), the normal, the albedo; and the upper
#: edges' spreads where the map has them (:func:`horizon_lookups`).
HORIZON_LOOKUPS = 4 * len(STRIPS) + 2
HORIZON_SPREAD_LOOKUPS = 2 * len(STRIPS)
#: ... and the open bands' two edges (a window's sky), where the map keeps them.
HORIZON_GAP_LOOKUPS = 4 * len(STRIPS)
#: ... and the azimuth gaps' crossings (a jamb's, a post's azimuth) with their weights, where
#: the map has them: two per strip across the disc.
HORIZON_CROSS_LOOKUPS = 2 * len(STRIPS)
#: ... and the bands' two edges' spreads over the footprints, where the map has them.
HORIZON_BAND_SPREAD_LOOKUPS = 4 * len(STRIPS)
#: A map's open bands are kept only where they bring its error against rays at the held-out
#: suns down by at least this much (relative): they cost 20 lookups per pixel (32 -> 52). On
#: the statue demo's statue (128^2, 24 azimuths) they brought the whole map from 0.126 to
#: 0.110 (T: 0.068) and, on its sampled tiles, from 0.126 to 0.092 against T's 0.079: the trial
#: undecided, the whole map found (16.95 M horizon rays, more than without a trial) only to be
#: rejected. On the gallery's interior (128^2) its box 0.80 -> 0.33, the scan's floor 0.093 ->
#: 0.039; the mutual shadows' and the fence's 0.065 and 0.257 with or without (2026-12-06).
GAP_GAIN = 0.2


def choose_bands(with_: dict, without: dict) -> dict:
    """The held-out errors (:func:`.horizon_map.heldout_errors`) of a map with open bands
    (``with_``) and without (``without``) -> those of the one kept (:data:`GAP_GAIN`), with
    ``without`` and ``open_bands``: whether they were kept, and both figures."""
    kept = with_["horizon"] < (1.0 - GAP_GAIN) * without["horizon"]
    return {**(with_ if kept else without), "without": without,
            "open_bands": {"kept": bool(kept), "heldout_with": round(with_["horizon"], 4),
                           "heldout_without": round(without["horizon"], 4)}}


def horizon_lookups(horizon) -> int:
    """Texture lookups per pixel of ``horizon``'s viewport."""
    return (HORIZON_LOOKUPS + (HORIZON_SPREAD_LOOKUPS if getattr(horizon, "spread", None)
                               is not None else 0)
            + (HORIZON_GAP_LOOKUPS if getattr(horizon, "gaps", False) else 0)
            + (HORIZON_CROSS_LOOKUPS if getattr(horizon, "cross", None) is not None else 0)
            + (HORIZON_BAND_SPREAD_LOOKUPS if getattr(horizon, "band_spread", None) is not None
               else 0))


def fit_model(store, settings: TransportTextureSettings, albedo):
    """The chosen model of one object's store (None for ``model="none"``)."""
    if settings.model == "pca":
        return tt.fit_texture_pca(store, k=settings.components,
                                  tol=None if settings.components else settings.tol)
    if settings.model == "blocks":
        return tt.fit_block_pca(store, block=settings.block, tol=settings.tol)
    if settings.model == "steerable":
        return steerable_from_store(store, albedo, order=settings.components or 7)
    return None


def fit_viewport(store, settings: TransportTextureSettings, model, lights=TRUTH_LIGHTS,
                 horizon=None, horizon_check=None):
    """What the live preview shows for one object's store: ``(BlockViewport or None, info)``.

    The block viewport is fitted when the settings resolve to it
    (:func:`.sparse_tables.choose_viewport`): its block side and components are the candidate
    with the lowest residual on sampled regions of T within the GPU budget
    (:func:`.block_viewport.choose`). Under ``auto`` the global PCA (``model``) is kept instead
    when it is measured closer to T at the held-out lights (direct light, the preview's sun).
    ``horizon_check``: ``(directions, rows)`` of rays against which ``horizon`` and T are
    checked, or the errors of a trial on sampled tiles that decided
    (:mod:`.horizon_trial`; ``horizon`` is then None where it rejected the map).
    ``info`` is the report's ``viewport`` entry: what is shown, why, and the figures."""
    from . import block_viewport as bv
    from . import sparse_tables as sp

    if settings.model != "pca":
        return None, {"shows": "none", "why": f"model {settings.model!r} has no live preview"}
    budget = int(settings.gpu_budget) << 20
    horizon_note = {}
    # a trial on sampled tiles (horizon_trial) that decided: its errors instead of a check's rays
    trial = horizon_check if isinstance(horizon_check, dict) else None
    if horizon is None and trial is not None and settings.viewport == "auto":
        horizon_note = {"horizon_rejected": (
            f"T is closer to rays at held-out suns on {trial['texels']} sampled texels "
            f"({trial['transport']:.3f} against the horizon map's {trial['horizon']:.3f}); the "
            f"map was not found whole"), "horizon": {"heldout": _heldout(trial)}}
    if horizon is not None and settings.viewport in ("auto", "horizon"):
        from . import horizon_map as hmap

        t0 = time.perf_counter()
        e = trial
        if horizon.gaps and horizon_check is not None and trial is None:
            # the open bands kept only where the check sees them help (GAP_GAIN)
            e = choose_bands(*(hmap.heldout_errors(m, store, *horizon_check,
                                                   settings.sun_angle, settings.kernel)
                               for m in (horizon, horizon.without_bands())))
        gaps = (e or {}).get("open_bands") if horizon.gaps else None
        # the bands' edges' spreads go with the bands, and first where over the budget (the
        # bake made them only where the whole map fits it)
        if horizon.band_spread is not None and ((gaps is not None and not gaps["kept"])
                                                or horizon.gpu_bytes() > budget):
            horizon.band_spread = None
        crossings = None
        if horizon.cross is not None:    # the gaps' crossings go first where over the budget
            crossings = {"kept": True}
            shown = horizon if gaps is None or gaps["kept"] else horizon.without_bands()
            if shown.gpu_bytes() > budget:
                horizon.cross = None
                crossings = {"kept": False, "why": "over the GPU budget with them"}
                if trial is None:  # (measured with them: measured again on the map shown)
                    e = None
                else:              # (a trial's tiles are not measured again)
                    crossings["heldout"] = "the trial's, measured with them"
        if (gaps is not None and gaps["kept"] and horizon.gpu_bytes() > budget
                and horizon.without_bands().gpu_bytes() <= budget):
            gaps = {**gaps, "kept": False, "why": "over the GPU budget with them"}
            if e is not None:
                e = {**e, **e["without"]}        # the figures of the map shown
        if gaps is not None and not gaps["kept"]:     # (in place: the map written is the one
            horizon.q = horizon.q[:2]                  # shown)
            horizon.band_spread = None
        mib = horizon.gpu_bytes() / 2**20
        info = {"azimuths": horizon.azimuths, "gpu_mib": round(mib, 1),
                "lookups_per_pixel": horizon_lookups(horizon),
                "gpu_budget_mib": settings.gpu_budget,
                **({"open_bands": gaps} if gaps is not None else {}),
                **({"crossings": crossings} if crossings is not None else {})}
        if horizon_check is not None:
            if e is None:
                e = hmap.heldout_errors(horizon, store, *horizon_check, settings.sun_angle,
                                        settings.kernel)
            info.update(heldout=_heldout(e), check_seconds=round(time.perf_counter() - t0, 3))
        if settings.viewport == "horizon":
            return None, {"shows": "horizon", "why": "asked for", **info}
        h = info.get("heldout")
        if h is not None and h["horizon"] <= h["transport"] and mib <= settings.gpu_budget:
            return None, {"shows": "horizon", "why": (
                f"auto: closer to rays at held-out suns than T ({h['horizon']:.3f} against "
                f"{h['transport']:.3f}) in {mib:.0f} MiB"), **info}
        horizon_note = {"horizon_rejected": (
            f"the horizon map takes {mib:.0f} MiB (over {settings.gpu_budget})"
            if mib > settings.gpu_budget else "no held-out check" if h is None else
            f"T is closer to rays at held-out suns ({h['transport']:.3f} against the horizon "
            f"map's {h['horizon']:.3f})"), "horizon": info}
    shows, why = sp.choose_viewport(settings.viewport, store.directions.size, store.resolution,
                                    budget_mib=settings.gpu_budget, table_size=settings.table_size)
    info = {"shows": shows, "why": why, "gpu_budget_mib": settings.gpu_budget, **horizon_note}
    if shows != "blocks":
        return None, info
    t0 = time.perf_counter()
    choice = bv.choose(store, settings.table_size, budget, seed=settings.seed)
    t_choose = time.perf_counter() - t0
    view = bv.fit(store, choice["block"], choice["k"], seed=settings.seed)
    rows = []
    for az, el in lights:
        idx, w = tt.sun_weights(store.directions, direction_from_az_el(az, el),
                                settings.sun_angle, settings.kernel)
        full = store.relight(idx, w)
        rows.append((rel_rmse(view.relight_weights(idx, w), full),
                     rel_rmse(model.relight(idx, w), full)))
    blocks_err = float(np.sqrt(np.mean([r[0] ** 2 for r in rows])))
    pca_err = float(np.sqrt(np.mean([r[1] ** 2 for r in rows])))
    g = view.gpu_bytes(settings.table_size)
    info.update({**view.summary(), "shows": "blocks", "choice": choice,
                 "gpu_mib": round(g["total_bytes"] / 2**20, 1),
                 "lookups_per_pixel": bv.lookups_per_pixel(view.k),
                 "blocks_vs_T": round(blocks_err, 4), "pca_vs_T": round(pca_err, 4),
                 "fit_seconds": round(time.perf_counter() - t0, 3),
                 # the choice fits sampled regions of at most the largest block's side, the
                 # same work at any texture side from 128^2 up (the estimate times it apart)
                 "choose_seconds": round(t_choose, 3)})
    if settings.viewport == "auto" and pca_err < blocks_err:
        info.update(shows="pca", why=f"auto: the PCA is closer to T ({pca_err:.3f}) than the "
                                     f"block viewport ({blocks_err:.3f})")
        return None, info
    return view, info


def _heldout(e: dict) -> dict:
    """The report's held-out check of the horizon map against T (whole, or on the trial's
    sampled texels)."""
    out = {"horizon": round(e["horizon"], 4), "transport": round(e["transport"], 4),
           "sun_angle": e["sun_angle"], "directions": e["directions"],
           "meaning": "relative RMSE of the direct light against hard suns by rays over the "
                      "sun's disc at held-out directions (3-85 degrees elevation)"}
    if "texels" in e:
        from .horizon_trial import DECISIVE

        out["sampled"] = {"texels": e["texels"], "of_texels": e["of_texels"],
                          "horizon_texels_found_first": e["tiles_texels"],
                          "decided": e["decided"],
                          "meaning": "the check ran on the texels of sampled tiles only "
                                     "(lt_addon/transport/horizon_trial.py), and one viewport "
                                     f"erred over {DECISIVE}x the other there"}
    return out


def steerable_from_store(store, albedo, order: int = 7):
    """The steerable basis of Ashikhmin & Shirley by quadrature over the baked directions:
    noise-free, any order, radiance of the direct light (albedo applied)."""
    from ..steerable.sampled_basis import build_sampled_basis
    from ..steerable.basis import paper_basis
    from ..steerable.texture import SteerableTexture

    basis = paper_basis(order)
    sampled = build_sampled_basis(basis)
    stack = tt.quadrature_sampled_lights(store, sampled)              # (K, R, R)
    rgb = stack[..., None] * np.asarray(albedo, np.float32)[None]
    return SteerableTexture(sampled.to_basis_images(rgb, dtype=np.float32), order, basis.width,
                            sampled.centres, frame="world", calibration="steerable_cos",
                            settings={"resolution": store.resolution, "mode": "radiance",
                                      "method": "transport-quadrature",
                                      "directions": store.directions.spec})


def upsample(img, R):
    """Bilinear resize of (r, r, C) to (R, R, C) at texel centres (as a GPU sampler would)."""
    img = np.asarray(img, np.float32)
    r = img.shape[0]
    if r == R:
        return img
    c = (np.arange(R) + 0.5) * r / R - 0.5
    c = np.clip(c, 0.0, r - 1.0)
    i0 = np.minimum(np.floor(c).astype(int), r - 2 if r > 1 else 0)
    f = (c - i0)[:, None]
    i1 = np.minimum(i0 + 1, r - 1)
    rows = img[i0] * (1 - f)[..., None] + img[i1] * f[..., None]
    return rows[:, i0] * (1 - f.T)[..., None] + rows[:, i1] * f.T[..., None]


#: what each viewport the bake chose (its report's ``viewport.shows``) relights from
VIEWPORT_SOURCES = {"horizon": "horizon", "transport": "transport", "pca": "model",
                    "blocks": "blocks", "none": "model"}


def viewport_source(bake: ObjectBake, environment: bool = False) -> str:
    """The source that relights what the panel's viewport shows for this bake (its report's
    ``viewport.shows``): ``horizon``, ``transport`` (T through its sparse tables: T),
    ``model`` (the PCA) or ``blocks``. Under an environment the viewport's environment group
    reads the PCA (``model``; T where there is none): a horizon map holds one sun's shadows."""
    shows = str((bake.viewport or {}).get("shows", "pca"))
    source = VIEWPORT_SOURCES.get(shows, "model")
    if source == "blocks" and bake.view is None:
        source = "model"
    if environment and source in ("horizon", "blocks"):
        source = "model"
    if source == "model" and bake.model is None:
        source = "transport"
    return source


def relight(bake: ObjectBake, store, direction, sun_angle: float = 0.0, intensity: float = 1.0,
            source: str = "transport", kernel: str = "linear") -> np.ndarray:
    """Radiance (R, R, 3) under a sun: ``source="transport"`` relights from T itself (the
    full-accuracy reference at T's directions), ``"model"`` from the fitted model,
    ``"horizon"`` from the horizon map, ``"blocks"`` from the block viewport, ``"viewport"``
    from whichever of them the viewport shows (:func:`viewport_source`: what the panel and its
    figures show). Texel by texel, the bake margin as Cycles' Extend fills it from the island
    (the horizon map's :meth:`.horizon_map.HorizonMap.direct`; the viewport's lookups read the
    map's own margin codes at an island's border)."""
    if source == "viewport":
        source = viewport_source(bake)
    idx, w = tt.sun_weights(store.directions, direction, sun_angle, kernel)
    R = store.resolution
    if source == "blocks":
        if bake.view is None:
            raise InputError(f"{bake.name}: this bake's viewport shows no blocks")
        direct = np.asarray(bake.view.relight_weights(idx, w)).reshape(R, R)[..., None] * bake.albedo
    elif source == "horizon":
        if bake.horizon is None:
            raise InputError(f"{bake.name}: this bake keeps no horizon map (its viewport shows "
                             f"{(bake.viewport or {}).get('shows', 'no horizons')}); use "
                             "--source model or transport")
        direct = bake.horizon.direct(direction, sun_angle)[..., None] * bake.albedo
    elif source == "transport" or bake.model is None:
        e = store.relight(idx, w)
        direct = e[..., None] * bake.albedo
    elif hasattr(bake.model, "relight") and hasattr(bake.model, "V"):
        e = bake.model.relight(idx, w)
        direct = e[..., None] * bake.albedo
    else:   # steerable texture
        direct = bake.model.relight(np.asarray(direction, np.float64))
    out = direct
    if bake.indirect is not None:
        out = out + upsample(indirect_images(bake.indirect, direction, sun_angle, kernel), R)
    return (intensity * out).astype(np.float32)


def relight_environment(bake: ObjectBake, store, env_image, rotation_deg: float = 0.0,
                        *, row_order: str = "top_first", source: str = "transport") -> np.ndarray:
    """Radiance (R, R, 3) under an equirectangular environment (upper hemisphere): direct
    light from T (``source="transport"``) or from the PCA model (``"model"``, what the
    viewport shows), plus the indirect term steered by the same environment
    (:func:`..lt_addon.transport.texture.steer_environment`)."""
    if source == "viewport":
        source = viewport_source(bake, environment=True)
    if source in ("horizon", "blocks"):
        raise InputError("an environment relights from T or the model (--source transport or "
                         "model): the horizon map and the blocks' tables hold one sun")
    w = tt.environment_weights(store.directions, env_image, row_order=row_order,
                               rotation_deg=rotation_deg)
    model = bake.model
    if source == "model" and hasattr(model, "relight_dense") and hasattr(model, "V"):
        e = model.relight_dense(w)
    else:
        e = store.relight_dense(w)
    out = (e if e.ndim == 3 else e[..., None]) * bake.albedo
    if bake.indirect is not None:
        B = direction_matrix(bake.indirect, store.directions)
        out = out + upsample(tt.steer_environment(bake.indirect, B, w), store.resolution)
    return out.astype(np.float32)


def rel_rmse(estimate, truth) -> float:
    e, t = np.asarray(estimate, np.float64), np.asarray(truth, np.float64)
    den = np.linalg.norm(t)
    return float(np.linalg.norm(e - t) / den) if den > 0 else float(np.linalg.norm(e) > 0)


def viewport_tables(settings, store, sun_angle: float | None = None):
    """The sparse kernel tables (indices, weights, kept) of the transport viewport when the
    settings choose it for this store, else None."""
    from . import sparse_tables as sp

    if settings.model != "pca":
        return None
    try:
        viewport, _ = sp.choose_viewport(settings.viewport, store.directions.size,
                                         store.resolution)
    except ValueError:
        return None
    if viewport != "transport":
        return None
    return sp.cached_tables(store.directions, max(sp.TABLE_SIZE, settings.table_size),
                            settings.sun_angle if sun_angle is None else sun_angle,
                            settings.kernel)


_QUANTIZED: dict = {}


def quantized(store):
    """(tiles, scales) of :func:`..lt_addon.transport.sparse_tables.quantize_directions` for
    ``store`` (cached per store file and its modification time)."""
    from . import sparse_tables as sp

    path = getattr(store, "_tmp", None) or store.path
    key = (os.path.abspath(path), os.path.getmtime(path) if os.path.exists(path) else 0.0,
           store.directions.size)
    if key not in _QUANTIZED:
        if len(_QUANTIZED) >= 4:      # a few stores (objects baked together): S * R^2 bytes each
            _QUANTIZED.clear()
        _QUANTIZED[key] = sp.quantize_directions(store.array)
    return _QUANTIZED[key]


def viewport_direct(store, tables, direction) -> np.ndarray:
    """What the transport viewport shows of the direct light (R, R), irradiance/pi: T through
    the sparse tables, read from its 8-bit atlas."""
    from . import sparse_tables as sp

    tiles, scales = quantized(store)
    return sp.viewport_relight(tiles, tables[0], sp.scaled_weights(tables[0], tables[1], scales),
                               direction, 1.0 / 255.0)


def model_fidelity(bake: ObjectBake, store, settings, lights=TRUTH_LIGHTS) -> dict | None:
    """How far what the viewport shows is from T itself (the offline relight) at the held-out
    lights, for the preview's sun size: direct light only (both add the same indirect term),
    relative RMSE per light and combined as ``sqrt(mean(rel^2))``. The viewport is T through
    sparse kernel tables (``viewport`` transport) or the fitted model; ``model_headline`` is
    the fitted model's figure either way. Needs no Cycles truth, so every bake reports it.
    None without a PCA-like model."""
    model = bake.model
    if model is None or not (hasattr(model, "V") or hasattr(model, "n_blocks")):
        return None                     # none, or the steerable basis (no sparse relight)
    view = getattr(bake, "view", None)
    hm = getattr(bake, "horizon", None)
    tables = None if view is not None or hm is not None else viewport_tables(settings, store)
    viewport = ("horizon" if hm is not None else "blocks" if view is not None else
                settings.model if tables is None else "transport")
    rows = []
    for az, el in lights:
        d = direction_from_az_el(az, el)
        idx, w = tt.sun_weights(store.directions, d, settings.sun_angle, settings.kernel)
        full = store.relight(idx, w)
        row = {"azimuth": az, "elevation": el, "model": rel_rmse(model.relight(idx, w), full)}
        row["rel"] = (rel_rmse(hm.direct(d, settings.sun_angle), full) if hm is not None else
                      rel_rmse(view.relight_weights(idx, w), full) if view is not None else
                      row["model"] if tables is None else
                      rel_rmse(viewport_direct(store, tables, d), full))
        rows.append(row)
    head = float(np.sqrt(np.mean([r["rel"] ** 2 for r in rows])))
    mhead = float(np.sqrt(np.mean([r["model"] ** 2 for r in rows])))
    worst = max(rows, key=lambda r: r["rel"])
    return {"headline": round(head, 4), "viewport": viewport,
            "model_headline": round(mhead, 4), "lights": rows, "sun_angle": settings.sun_angle,
            "worst": {"rel": round(worst["rel"], 4), "elevation": worst["elevation"]},
            "meaning": "relative RMSE of the viewport's relight against T's (direct light, "
                       "albedo left out) at the held-out lights: how far the viewport is from "
                       "the bake's own relight (relight --source transport); model_headline: "
                       "the same for the fitted model. Not an error against Cycles: T blends "
                       "neighbouring directions' shadows, and a PCA that smooths them can even "
                       "be closer to Cycles (bumps demo, 2-degree Sun: 0.101 vs T's 0.103, "
                       "while 0.056 apart). A global PCA loses cast shadows on large receivers "
                       "(statue demo's ground, PCA 96: 0.064, 0.102 at 10 degrees elevation); "
                       "the transport viewport keeps them (bumps demo, 64^2 tables: 0.005), "
                       "and so does the block viewport (bumps demo 256^2, 8^2 blocks of 24 "
                       "components: 0.025)"}


def model_summary(model, S: int) -> dict:
    """The report's model entry; a steerable quadrature model or none have no PCA summary."""
    if model is None:
        return {"kind": "none"}
    if hasattr(model, "summary"):
        return model.summary(S)
    return {"kind": "steerable", "order": model.order}


_BAKED = object()


def indirect_lookups(settings, term=_BAKED) -> int:
    """Texture lookups per pixel of the indirect term's viewport group: the steerable term's
    order^2 basis images; the gathered term's k component images and its ceil(k / 3) tables of
    coefficients over the sun's disk. ``term``: the baked term (GatheredIndirect,
    SteerableTexture or None: what was made, a fallback included); else from the settings."""
    if term is not _BAKED:
        if term is None:
            return 0
        if isinstance(term, GatheredIndirect):
            return term.components + -(-term.components // 3)
        return int(term.order) ** 2
    if not settings.bounces or settings.indirect == "none":
        return 0
    if settings.indirect == "gather":
        k = int(settings.indirect_components)
        return k + -(-k // 3)
    return settings.indirect_order ** 2


def preview_cost(model, settings, store=None, view=None, horizon=None, indirect=_BAKED) -> dict:
    """Per-pixel cost of the live preview of ``model`` as ``settings.viewport`` shows it (the
    transport viewport: 4 table texels x (2 K / 3 table lookups + K atlas lookups) + the
    albedo, K the taps its tables need for the preview's sun size: 21 lookups for a point sun,
    whatever the number of directions)."""
    if not hasattr(model, "preview_cost"):
        return {}
    extra = indirect_lookups(settings, indirect)
    if horizon is not None:
        return {"viewport": "horizon", "azimuths": horizon.azimuths,
                "texture_lookups_per_pixel": horizon_lookups(horizon) + extra,
                "python_per_light_change": False,
                "gpu_mib": round(horizon.gpu_bytes() / 2**20, 1)}
    if view is not None:
        from . import block_viewport as bv

        g = view.gpu_bytes(settings.table_size)
        return {"viewport": "blocks", "block": view.block, "components": view.k,
                "texture_lookups_per_pixel": bv.lookups_per_pixel(view.k) + extra,
                "multiply_adds_per_texel": 3 * -(-view.k // 3),
                "python_per_light_change": False,
                "gpu_mib": round(g["total_bytes"] / 2**20, 1)}
    tables = viewport_tables(settings, store) if store is not None else None
    if tables is not None:
        from . import sparse_tables as sp

        taps = tables[0].shape[-1]
        side, nbytes = sp.atlas_layout_bytes(store.directions.size, model.resolution)
        return {"viewport": "transport", "taps": taps,
                "texture_lookups_per_pixel": 4 * (2 * taps // 3 + taps) + 1 + extra,
                "multiply_adds_per_texel": 4 * taps, "python_per_light_change": False,
                "atlas_side": side, "atlas_mib_8bit": round(nbytes / 2**20, 1)}
    return {"viewport": "pca", **model.preview_cost(extra)}


#: The report's ``files`` a checksum is recorded for, and the order they are checked in.
CHECKSUMMED = ("transport", "albedo", "indirect", "model", "viewport_blocks", "horizons")


def file_checksums(files: dict) -> dict:
    """``{key: "sha256:<hex>"}`` of a bundle's files (:func:`..io.untrusted.file_checksum`),
    recorded in the report at bake time so a reader can tell a file changed after the bake.
    T is hashed too (0.5-1.7 s/GiB, once per bake), whatever its size: a reader verifies it
    when it is at most :data:`..io.untrusted.CHECKSUM_MAX_BYTES` (256 MiB)."""
    out = {k: untrusted.file_checksum(files[k]) for k in CHECKSUMMED if k in files}
    if "transport" in files:   # T's header: its resolution and directions
        out["transport_header"] = untrusted.file_checksum(
            tt.TransportStore.header_path(files["transport"]))
    return out


def _report_settings(report: dict, path: str) -> dict:
    """The report's ``settings``, with the fields readers size or index by checked: the sun
    size (degrees), the viewport table size (D, a D x D table; a D^2 loop), the kernel."""
    s = untrusted.field(report, "settings", path, dict)
    angle = untrusted.field(s, "sun_angle", path, float, where="settings")
    if not 0.0 <= angle <= 90.0:
        raise untrusted.UntrustedFileError(path, f"settings.sun_angle {angle} is not in 0..90")
    if "table_size" in s:
        untrusted.check_count(path, untrusted.field(s, "table_size", path, int,
                                                    where="settings"),
                              256, "settings.table_size", lo=8)
    if "kernel" in s and untrusted.field(s, "kernel", path, str, where="settings") \
            not in tt.KERNELS:
        raise untrusted.UntrustedFileError(path, f"settings.kernel {s['kernel']!r:.40} is not "
                                                 f"one of {', '.join(tt.KERNELS)}")
    return s


def load_bake(report_path: str) -> tuple:
    """(ObjectBake, TransportStore, report) from a report written by :func:`write_bundle`.

    The report and every file it names are read as files from elsewhere
    (:mod:`..io.untrusted`): the report is a capped regular JSON file; the files are found by
    their basenames in the report's folder (no link is followed, no other folder read); each
    file's checksum, when the report records one (bakes from before have none), must match
    (T only up to :data:`..io.untrusted.CHECKSUM_MAX_BYTES`: a larger T is checked by its
    header and its values' range as it is read); the stores and models check their own
    headers and values. Anything else is one :class:`..io.untrusted.UntrustedFileError`
    naming the file."""
    from ..steerable.texture import SteerableTexture

    rp = os.path.abspath(report_path)
    report = untrusted.read_json(rp)
    kind = untrusted.field(report, "kind", rp, str, KIND)
    if kind != KIND:
        raise InputError(f"{report_path}: a {kind!r} report, not a transport texture bake's")
    found = max(untrusted.field(report, "format", rp, int, 1),
                untrusted.field(report, "format_version", rp, int, 1))
    if found > FORMAT:
        raise InputError(f"{report_path}: bundle format {found} is newer than this "
                         f"version reads ({FORMAT}); update Relightable Textures")
    report["report"] = rp
    untrusted.field(report, "object", rp, str)
    _report_settings(report, rp)
    files = untrusted.field(report, "files", rp, dict)
    sums = untrusted.field(report, "checksums", rp, dict, {})
    folder = os.path.dirname(rp)

    def where(key):   # the report's folder may have moved with the files: basenames only
        name = os.path.basename(untrusted.field(files, key, rp, str, where="files"))
        path = untrusted.confined(folder, name, must_exist=True, folder=False)
        if key == "transport":   # T's data (up to the cap) and its header
            untrusted.check_checksum(path, sums.get(key))
            untrusted.check_checksum(tt.TransportStore.header_path(path),
                                     sums.get("transport_header"))
        else:
            untrusted.check_checksum(path, sums.get(key), max_bytes=untrusted.MAX_ARRAY_BYTES)
        return path

    store = tt.TransportStore.open(where("transport"))
    albedo_path = where("albedo")
    ch, meta = exrio.read_exr(albedo_path)
    if meta:   # (albedos before versioning carry a format but no version: 1)
        versions.check(meta, "relightable_textures.albedo", albedo_path, "an albedo")
    albedo = exrio.stack_channels(albedo_path, ch, "RGB", (store.resolution, store.resolution))
    indirect = None
    if "indirect" in files:
        ip = where("indirect")
        indirect = (GatheredIndirect.load(ip, store.directions) if ip.endswith(".npz")
                    else SteerableTexture.load(ip))
    model = None
    if "model" in files:
        m = where("model")
        model = SteerableTexture.load(m) if m.endswith(".exr") else tt.load_model(m, store)
    view = None
    if "viewport_blocks" in files:
        from . import block_viewport as bv

        view = bv.load(where("viewport_blocks"), store)
    horizon = None
    if "horizons" in files:
        from . import horizon_map as hmap

        horizon = hmap.load(where("horizons"), store.resolution)
    return ObjectBake(report["object"], store.path, albedo, indirect, model, view=view,
                      viewport=report.get("viewport"), horizon=horizon), store, report


def indirect_summary(term, settings) -> dict:
    """How the indirect term was made, for the report: its method and figures."""
    if term is None:
        return {"method": "none", "why": ("the scene has no bounces" if not settings.bounces
                                           else "indirect: none")}
    if isinstance(term, GatheredIndirect):
        return {**term.settings, "bytes": term.storage_bytes()}
    return {"method": "steerable", "order": int(term.order), "resolution": term.resolution,
            "samples": term.settings.get("samples"),
            **{k: term.settings[k] for k in ("why", "gather_check") if k in term.settings}}


def write_bundle(result: TransportTextureResult, names: list, out_dir: str,
                 figures: dict | None = None, started: float | None = None,
                 device: dict | None = None, version: str = "") -> list:
    """Write per object (``names``: the objects baked together, in ``result.objects`` order):
    albedo + indirect EXRs, the model (NPZ or EXR) and the report JSON (:data:`FORMAT`).
    Returns the reports, each with its path under ``"report"``. ``device``: the Cycles device
    the bake ran on (the bpy layer's report); ``version``: the add-on's."""
    from ..steerable.texture import SteerableTexture

    s = result.settings
    if (s.bounces is not None and s.bounces < 0) or (s.sun_angle is not None and s.sun_angle < 0):
        raise ValueError("the settings leave the bounces or the Sun size to the scene (-1): "
                         "take them from it first (texture_transport.scene_light_settings)")
    t0 = time.perf_counter()
    reports = []
    for b in result.objects:
        base = os.path.join(out_dir, object_stem(b.name))
        if b.store is not None and getattr(b.store, "_tmp", None):
            b.store_path = b.store.commit()
        files = {"transport": b.store_path}
        files["albedo"] = base + "_albedo.exr"
        exrio.write_exr(files["albedo"], {c: b.albedo[..., i] for i, c in enumerate("RGB")},
                        {"format": "relightable_textures.albedo"}, pixel_type="half")
        faults.checkpoint("write", files["albedo"])
        if b.indirect is not None:   # gathered: images and coefficients in one NPZ
            files["indirect"] = base + ("_indirect.npz" if isinstance(b.indirect, GatheredIndirect)
                                        else "_indirect.exr")
            b.indirect.save(files["indirect"], "half")
        if b.model is not None:
            if isinstance(b.model, SteerableTexture):
                files["model"] = base + "_transport_steerable.exr"
                b.model.save(files["model"], "half")
            else:
                files["model"] = base + "_transport_model.npz"
                tt.save_model(files["model"], b.model, result.directions.spec)
        if b.view is not None:
            from . import block_viewport as bv

            files["viewport_blocks"] = base + "_viewport_blocks.npz"
            bv.save(files["viewport_blocks"], b.view)
        if b.horizon is not None:
            from . import horizon_map as hmap

            files["horizons"] = base + "_horizons.npz"
            hmap.save(files["horizons"], b.horizon)
        nbytes = {k: os.path.getsize(v) for k, v in files.items()}
        sums = file_checksums(files)
        s = result.settings
        store = b.store or tt.TransportStore.open(b.store_path)
        report = {
            "kind": KIND, "format": FORMAT, "format_version": FORMAT, "addon_version": version, "object": b.name, "method": "transport",
            "settings": asdict(s), "directions": result.directions.size,
            # the spec asked for (the set itself may add a Sun's path and the band under the
            # horizon: ``direct.direction_set`` says what it added)
            "direction_set": s.directions,
            "objects_baked_together": list(names),
            "files": {k: os.path.abspath(v) for k, v in files.items()},
            "checksums": sums,
            "bytes": {**nbytes, "total": int(sum(nbytes.values())),
                      **(b.model.storage_bytes() if hasattr(b.model, "storage_bytes") else {})},
            "model": model_summary(b.model, result.directions.size),
            "timings": {k: round(v, 3) for k, v in result.seconds.items()},
            "device": device or {},
            "direct": result.direct or {"engine": "cycles"},
            "indirect": indirect_summary(b.indirect, s),
            "bake_calls": result.bake_calls,
            "peak_rss_above_start_mb": round(result.peak_rss_mb, 1),
            "rss_growth_while_streaming_mb": round(result.growth_after_first_mb, 1),
            "peak_rss_by_stage_mb": result.peak_by_stage_mb,
            "preview_cost": preview_cost(b.model, s, store, b.view, b.horizon, b.indirect),
            "viewport": b.viewport or {},
            "model_vs_T": model_fidelity(b, store, s),
            **result.chunks,
            **(figures or {}),
        }
        report["timings"]["write"] = round(time.perf_counter() - t0, 3)
        if started is not None:
            report["timings"]["wall_total"] = round(time.perf_counter() - started, 3)
        path = base + "_texture_report.json"
        atomic.write_json(path, report, default=float)
        report["report"] = os.path.abspath(path)
        reports.append(report)
    return reports
