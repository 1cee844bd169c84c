"""The texture transport bake's direct stage by rays (bpy): choose the engine, read the scene into
arrays, and stream ``T[s]`` into the stores in chunks of directions.

Cycles keeps what only it can do -- albedo, the shading normals of normal-mapped materials (1-spp
NORMAL bakes at shifted texel centres: :func:`sampled_normals`), the indirect term and every
truth; rays give visibility x cosine
(:mod:`...lt_addon.rays`). A scene rays cannot reproduce (alpha-transparent casters, hair, volumes,
true displacement) is baked by Cycles calls under ``--direct auto`` and refused under
``--direct rays``; the report says which engine baked and why.
"""

from __future__ import annotations

import contextlib
import time

import numpy as np

from ...lt_addon.errors import InputError
from ...lt_addon.rays import engine as ray_engine
from ...lt_addon.rays import horizon
from ...lt_addon.transport import bundle, horizon_map as hmap
from ...lt_addon.transport import horizon_trial
from ...lt_addon.rays.direct import direct_rows
from ...lt_addon.rays.footprint import HORIZON_LATTICE
from ...lt_addon.rays.texels import extend_margin
from ..base import cycles_device, ray_scene
from ..base.jobs import Progress

#: Directions per ray chunk at most (one engine call each; 64 x 65k texels = 4 M rays).
RAY_CHUNK = 64
#: Rays per engine call at most: a call holds ~45 bytes per ray (origin, direction, index,
#: result) next to its (directions x texels) rows, so 4 M rays keep it near 200 MB at any size
#: (64 directions of a 1024^2 ground held 2.9 GB: the statue bake at 1024^2 peaked at 4.1 GB
#: of anonymous memory, and 4096^2 would have asked for 46 GB).
RAY_BUDGET = 4 << 20


def ray_chunk(texels: int) -> int:
    """Directions per engine call for receivers of ``texels`` shading points: as many as
    :data:`RAY_BUDGET` allows, 1 .. :data:`RAY_CHUNK`."""
    return int(min(RAY_CHUNK, max(1, RAY_BUDGET // max(int(texels), 1))))


def choose(scene, objects, settings) -> dict:
    """Which engine bakes the direct term: ``{"engine": "rays" | "cycles", "why": ...}``.
    ``--direct rays`` on a scene rays cannot reproduce raises InputError with the reasons."""
    if settings.direct == "cycles":
        return {"engine": "cycles", "why": "asked for (--direct cycles)"}
    ok, lib = ray_engine.available()
    if not ok:
        if settings.direct == "rays":
            raise InputError(f"--direct rays: the ray engine is not available here: {lib}")
        return {"engine": "cycles", "why": f"no ray engine: {lib}"}
    with ray_scene.RenderGeometry(scene) as depsgraph:
        why = ray_scene.unsupported(scene, depsgraph, objects)
    if why:
        if settings.direct == "rays":
            raise InputError("--direct rays cannot reproduce this scene's direct light: "
                             + "; ".join(why) + " (use --direct cycles or auto)")
        return {"engine": "cycles", "why": "rays cannot reproduce: " + "; ".join(why)}
    return {"engine": "rays", "why": "the scene is supported", "library": lib,
            "threads": ray_engine.default_threads()}


def needs_normals(objects) -> list:
    """Which objects need Cycles' shading normals (normal or bump mapped), as booleans."""
    return [ray_scene.normal_mapped(o) for o in objects]


def world_normals(obj, object_normals):
    """Object-space unit normals (R, R, 3) of a Cycles NORMAL bake -> world space (zeros kept)."""
    M = np.array(obj.matrix_world, np.float64)[:3, :3]
    n = object_normals @ np.linalg.pinv(M)      # n_world = inv(M)^T n  (row vectors)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.where(length > 0, n / np.maximum(length, 1e-30), 0.0)


def sampled_normals(scene, objects, mapped, resolution: int, seed: int = 0):
    """``(normals, figures)``: the closure normals of the ``mapped`` objects (a list of
    booleans; None for the others) as :class:`...lt_addon.rays.normal_samples.TexelNormals`,
    sampled over each texel's jitter box by 1-spp NORMAL bakes at shifted texel centres, in a
    bake session of those objects alone (the others' meshes are not touched). Where a mesh
    takes no UV map of ours (linked data, eight maps, modifiers that change its UV map) every
    object keeps the centre's normal alone, and the figures say why."""
    import bpy

    from ...lt_addon.rays import normal_samples as ns
    from ...lt_addon.rays.footprint import jitter_box
    from ..base.cycles_bake import EnvironmentBake

    t0 = time.perf_counter()
    which = [i for i, m in enumerate(mapped) if m]
    objs = [objects[i] for i in which]
    lattice = ns.lattice_for(resolution * resolution * len(objs))
    offsets = ns.offsets(lattice, jitter_box(bpy.app.version))
    why = None

    def collect(images_per_offset, offs):
        samplers = [ns.Sampler(len(offs)) for _ in objs]
        try:
            for baked in images_per_offset:
                for smp, o, n in zip(samplers, objs, baked):
                    smp.add(world_normals(o, n))
        finally:       # a generator's temporary UV maps go now, not when it is collected
            close = getattr(images_per_offset, "close", None)
            if close is not None:
                close()
        return [smp.done(offs) for smp in samplers]

    with EnvironmentBake(scene, objs, resolution, 1, 0, (8, 16), mode="irradiance", seed=seed,
                         world_sampling="none", passes="color") as session:
        try:
            got = collect(session.bake_shifted_normals(offsets) if len(offsets) > 1
                          else [session.bake_normals()], offsets)
        except MemoryError:
            raise
        except Exception as e:    # linked data, a ninth UV map, modifiers that change ours
            why = str(e).splitlines()[0] if str(e) else type(e).__name__
            lattice, offsets = (1, 0), ns.offsets((1, 0), 1.0)
            got = collect([session.bake_normals()], offsets)
    normals = [None] * len(objects)
    for i, t in zip(which, got):
        normals[i] = t
    figures = {"lattice": [int(lattice[0]), int(lattice[1])], "bakes": int(len(offsets)),
               "varying_texels": int(sum(len(t.pixels) for t in got)),
               "seconds": round(time.perf_counter() - t0, 3)}
    if why:
        figures["centre_only_because"] = why
    return normals, figures


def _blas_idle():
    """BLAS at one thread for the block, unless RELIGHT_BLAS_POLICY=off (cycles_device)."""
    import contextlib

    from ...lt_addon import blas_threads

    return blas_threads.limited(1) if cycles_device.blas_policy() else contextlib.nullcontext()


#: Held-out directions of the viewport check, and hard suns over each one's disc.
HELDOUT, HELDOUT_DISC = 16, 8


def _disc(d, radius, count):
    """Hard-sun directions spread over a sun's disc (the transport relight's own)."""
    from ...lt_addon.transport.texture import _disc_points

    return _disc_points(np.asarray(d, np.float64), radius, count)


def _nearest(image, side: int):
    """An (R, R, 3) image (or None) read at the texel centres of a coarser ``side``: the
    nearest texel (the closure normals of normal-mapped objects, for the horizons' points)."""
    if image is None:
        return None
    image = getattr(image, "mean", image)      # sampled normals: their mean
    R = image.shape[0]
    i = np.minimum(((np.arange(side) + 0.5) * R / side).astype(np.int64), R - 1)
    return np.asarray(image)[i][:, i]


#: Azimuths the estimate's calibration bakes find horizons at whatever their viewport (they
#: force the block viewport to time its fit, which alone would make no map): see
#: :func:`calibration_horizons`.
_CALIBRATION_AZIMUTHS = None


@contextlib.contextmanager
def calibration_horizons(azimuths: int):
    """Within it, :func:`horizon_count` is ``azimuths`` for every bake (the estimate's
    calibration bakes, so that the horizons are timed with the block fit)."""
    global _CALIBRATION_AZIMUTHS
    before, _CALIBRATION_AZIMUTHS = _CALIBRATION_AZIMUTHS, int(azimuths)
    try:
        yield
    finally:
        _CALIBRATION_AZIMUTHS = before


def horizon_count(settings) -> int:
    """Azimuths of the horizon maps this bake makes (0: none): only where the viewport may show
    them (``auto`` or ``horizon``, a PCA model) and the settings ask for some."""
    if _CALIBRATION_AZIMUTHS is not None:
        return _CALIBRATION_AZIMUTHS
    if settings.model != "pca" or settings.viewport not in ("auto", "horizon"):
        return 0
    A = int(settings.horizon_azimuths)
    if settings.viewport == "auto" and A and hmap.gpu_bytes(
            A, settings.resolution, settings.horizon_resolution) > int(settings.gpu_budget) << 20:
        return 0       # auto could not show it (explicit horizon is refused before the bake)
    return A


def _crossings(occluder, points, H, figures: list, who: str, step: int, total: int,
               rows=None):
    """Generator: the crossings and their weights ``(t, w)`` (A, P) each of the intervals
    ``H`` of ``points`` (only ``rows``, where given: :func:`...lt_addon.rays.crossing.
    iter_crossings`), yielding Progress as
    "horizon crossings k/P points<who>"; their figures (with their seconds) appended to
    ``figures``."""
    from ...lt_addon.rays import crossing

    t0 = time.perf_counter()
    P = points.size if rows is None else len(rows)
    t, w, figs = yield from _progress(crossing.iter_crossings(occluder, points, H, rows), P,
                                      lambda done: f"horizon crossings {done}/{P} points{who}",
                                      step, total)
    figures.append({**figs, "seconds": time.perf_counter() - t0})
    return t, w


def _footprint_parts(pts, texels, want, A: int):
    """The footprints' sub-samples of ``texels`` and their (azimuth, point) pairs ``want``
    (A, P) bool, a part of the texels at a time (:data:`FOOTPRINT_BYTES`): yields ``(j,
    parts, idx, sub, weight, centre_w, fa, fk, count, group, rows)`` -- the part's index and
    count, its texels, their sub-samples (:data:`...lt_addon.rays.footprint.HORIZON_LATTICE`,
    ``Footprint._sub_points``), the pairs' azimuths and places in ``idx`` (m,), each pair's
    sub-samples' count (m,), and per sub-sample row its pair and its point in ``sub``."""
    n = HORIZON_LATTICE[0]
    part = max(1, FOOTPRINT_BYTES // (64 * n * A))     # sub-samples' points and pairs a part
    parts = -(-len(texels) // part)
    for j, a0 in enumerate(range(0, len(texels), part)):
        idx = texels[a0:a0 + part]
        owner, sub, weight, centre_w = pts.footprint._sub_points(pts, idx, HORIZON_LATTICE)
        start = np.searchsorted(owner, np.arange(len(idx) + 1))
        fa, fk = np.nonzero(want[:, idx])                   # the part's pairs (azimuth, texel)
        c = np.diff(start)[fk]
        group = np.repeat(np.arange(len(fa)), c)
        rows = np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c) + np.repeat(start[fk], c)
        yield j, parts, idx, sub, weight, centre_w, fa, fk, c, group, rows


#: How far from the texel centre's band edge a sub-sample's is sought (radians), and the
#: bisection steps within that bracket: 10 degrees / 2^8 = 0.04 degrees (2^6 = 0.16 degrees
#: read as a spread of its own that widened a 0.526-degree Sun's cut by half).
BAND_BRACKET = np.radians(5.0)
BAND_STEPS = 8


def _band_edge(occluder, sub, rows, phi, lo, hi, low_blocked: bool):
    """The elevation (n,) where the rays of sub-samples ``rows`` (n,) along azimuths ``phi``
    change between ``lo`` and ``hi`` (n,): blocked under it and open over it
    (``low_blocked``), or the reverse; outside the bracket, the bracket's end that its rays
    say. Returns ``(edge, rays)``."""
    from ...lt_addon.rays.shading import shadow_origins

    cp, sp_ = np.cos(phi), np.sin(phi)

    def blocked(e):
        ce = np.cos(e)
        L = np.stack([ce * cp, ce * sp_, np.sin(e)], -1)
        return occluder.occluded(shadow_origins(sub, L, rows), L.astype(np.float32))
    a, b = lo.copy(), hi.copy()
    at_a, at_b = blocked(a), blocked(b)
    inside = (at_a == low_blocked) & (at_b != low_blocked)
    for _ in range(BAND_STEPS):
        m = 0.5 * (a + b)
        under = blocked(m) == low_blocked
        a, b = np.where(under, m, a), np.where(under, b, m)
    edge = np.where(inside, 0.5 * (a + b), np.where(at_a != low_blocked, lo, hi))
    return edge, len(rows) * (2 + BAND_STEPS)


def _band_footprints(occluder, smp, pts, H, A: int, who: str, step: int, total: int):
    """Generator: the open bands' edges over the footprints of the (azimuth, point) pairs of
    ``H`` (4, A, P) that have a band (``H[3] > H[2]``) whose edges differ from a grid
    neighbour's, or that a neighbour lacks (:func:`...lt_addon.transport.horizon_map.
    varying_pairs` of the bands, ``smp`` the points' texels: elsewhere the footprint's band is
    the centre's, and a sub-sample on another face around an edge would shut it), and whose
    two neighbouring azimuths have a band too (beside one without, a jamb's vertical edge
    shuts it, which the crossings draw): each texel's sub-samples
    (:data:`...lt_addon.rays.footprint.HORIZON_LATTICE`) tested at the band's middle (shut
    there: no band) and their edges bisected within :data:`BAND_BRACKET` of the centre's
    (:func:`_band_edge`), kept as the weighted means and spreads
    (:func:`...lt_addon.transport.horizon_map.band_edges`): the means into ``H[2:]``, returns
    ``(spreads (2, A, P) float32 radians, figures)``."""
    from ...lt_addon.rays.shading import shadow_origins

    t0 = time.perf_counter()
    spreads = np.zeros((2, A, H.shape[2]), np.float32)
    band = H[3] > H[2]
    # (not beside an azimuth without the band: there a vertical edge -- a jamb -- shuts it,
    # which the crossings draw; its sub-samples shut too would darken it twice)
    band = (band & np.roll(band, 1, axis=0) & np.roll(band, -1, axis=0)
            & hmap.varying_pairs(H[2:], smp.texel, smp.resolution))
    texels = np.nonzero(band.any(axis=0))[0]
    points = pairs = rays = 0
    for j, parts, idx, sub, weight, centre_w, fa, fk, c, group, rows in _footprint_parts(
            pts, texels, band, A):
        points += sub.size
        pairs += len(fa)
        t = idx[fk]
        g_lo = H[2, fa, t].astype(np.float64)
        g_hi = H[3, fa, t].astype(np.float64)
        mid = 0.5 * (g_lo + g_hi)
        phi = 2 * np.pi * np.repeat(fa, c) / A
        lo_c, hi_c, mid_s = g_lo[group], g_hi[group], mid[group]
        top = np.pi / 2 - 1e-6
        L = np.stack([np.cos(mid_s) * np.cos(phi), np.cos(mid_s) * np.sin(phi),
                      np.sin(mid_s)], -1)
        shut = occluder.occluded(shadow_origins(sub, L, rows), L.astype(np.float32))
        lo_s, r1 = _band_edge(occluder, sub, rows, phi, np.maximum(lo_c - BAND_BRACKET, -top),
                              np.minimum(lo_c + BAND_BRACKET, mid_s), True)
        hi_s, r2 = _band_edge(occluder, sub, rows, phi, np.maximum(hi_c - BAND_BRACKET, mid_s),
                              np.minimum(hi_c + BAND_BRACKET, top), False)
        rays += len(rows) + r1 + r2
        m_lo, m_hi, s_lo, s_hi = hmap.band_edges(g_lo, g_hi, lo_s, hi_s, shut, group,
                                                 weight[rows], centre_w[fk])
        H[2, fa, t], H[3, fa, t] = m_lo, m_hi
        spreads[0, fa, t], spreads[1, fa, t] = s_lo, s_hi
        yield Progress(step, total, f"horizon bands over footprints "
                                    f"{j + 1}/{parts}{who}")
    return spreads, {"texels": int(len(texels)), "pairs": int(pairs), "points": int(points),
                     "rays": int(rays), "seconds": time.perf_counter() - t0}


def horizon_spread(settings) -> bool:
    """Whether this bake's horizon maps get their edges' spread over the texels' footprints
    (:func:`...lt_addon.transport.horizon_map.pair_edges`): where the texels are sampled
    by footprint, the horizons are at the texture's side (a coarser map's points are its own
    texel centres, with no footprint) and the map with its spreads fits the GPU budget (else
    the edges alone)."""
    A = horizon_count(settings)
    R = settings.resolution
    return bool(A) and getattr(settings, "texel_sampling", "footprint") == "footprint" and \
        hmap.side(R, settings.horizon_resolution) == R and \
        hmap.gpu_bytes(A, R, settings.horizon_resolution, spread=True) <= \
        int(settings.gpu_budget) << 20


def bake(scene, objects, settings, dset, stores, normals, step: int, total: int, margin: int = 4):
    """Generator: fill ``stores`` (one per object, (S, R*R)) with the ray-traced direct
    transport; ``normals``: per object world closure normals (R, R, 3) or None; ``margin``: the
    bake sessions' margin (EnvironmentBake's, Extend type), filled alike. Yields Progress
    from ``step``; returns figures (seconds, rays, rays per second, casters, triangles)."""
    R = settings.resolution
    A = horizon_count(settings)
    Rh = hmap.side(R, settings.horizon_resolution)
    t0 = time.perf_counter()
    with ray_scene.RenderGeometry(scene) as depsgraph:
        V, T, n_casters = ray_scene.casters(depsgraph)
        occluder = ray_engine.Occluder(V, T, threads=cycles_device.current().threads)
        footprint = getattr(settings, "texel_sampling", "footprint") == "footprint"
        receivers = [ray_scene.receiver_points(o, depsgraph, R, nrm, footprint=footprint)
                     for o, nrm in zip(objects, normals)]
        # the horizons at their own (coarser) side: their own texel centres
        coarse = ([ray_scene.receiver_points(o, depsgraph, Rh, _nearest(nrm, Rh),
                                             footprint=False)
                   for o, nrm in zip(objects, normals)] if A and Rh < R else None)
        # points touching another object's surface (a box's bottom on its floor): Cycles'
        # rays meet it at once (lt_addon/rays/contact.py)
        touching = ray_scene.with_contacts(depsgraph, [(o.name, pts) for o, (_, pts)
                                                       in zip(objects, receivers)],
                                           threads=cycles_device.current().threads)
    t_scene = time.perf_counter() - t0
    margins = [extend_margin(smp.covered(), margin) for smp, _ in receivers]
    S = dset.size
    chunk = ray_chunk(max(smp.size for smp, _ in receivers))
    t1 = time.perf_counter()
    eta = None
    # the rows and the covered texels' values, made once and reused by every chunk (fresh
    # arrays per chunk were page faults: see direct.POINT_BLOCK)
    rows = np.zeros((chunk, R * R), np.float32)
    inside_buf = np.empty((chunk, max(smp.size for smp, _ in receivers)), np.float32)
    for a in range(0, S, chunk):
        D = dset.directions[a:a + chunk]
        with _blas_idle():   # the ray engine's threads have the cores
            for store, (smp, pts), (dst, op) in zip(stores, receivers, margins):
                out = rows[:len(D)]
                out[...] = 0.0
                inside = direct_rows(occluder, pts, D, inside_buf[:, :smp.size])
                for row, vals in zip(out, inside):    # (row by row: a 2-D scatter of 64 x
                    row[smp.texel] = vals             # 65k took 6x as long on the bumps)
                if dst.size:
                    out[:, dst] = (op @ inside.T).T
                store.write_rows(a, out)
        done = min(a + chunk, S)
        rate = (time.perf_counter() - t1) / done
        eta = rate * (S - done)
        yield Progress(step + done - 1, total,
                       f"direction {done}/{S} (rays, about {eta:.0f} s left)")
    maps, horizon_info = None, {}
    if A:
        t2, r2 = time.perf_counter(), occluder.rays
        # the check auto chooses the viewport by: hard suns by rays over the preview sun's
        # disc at held-out directions (neither set has them), per object, margins filled
        # (on the scene Sun's animated path where the set holds it: the Sun the viewport
        # shows moves along it)
        n_path = int((dset.params or {}).get("sun_path_directions", 0))
        Dh = hmap.heldout_directions(HELDOUT, settings.seed,
                                     dset.directions[-n_path:] if n_path > 1 else None)
        trial_ok = settings.viewport == "auto" and _CALIBRATION_AZIMUTHS is None
        maps, skipped, searched, castable, checks, trials = [], 0, 0, 0, [], []
        gap_rays, gap_maps = 0, 0
        cross_figs, band_figs = [], []
        edges, with_spread = [], horizon_spread(settings)
        for i, ((smp, pts), mg, store) in enumerate(zip(receivers, margins, stores)):
            if coarse is None:
                h_smp, h_pts, low = smp, pts, None
            else:        # the margin in the horizons' texels, at least one
                h_smp, h_pts = coarse[i]
                low = (h_smp.texel, Rh,
                       extend_margin(h_smp.covered(), max(1, -(-margin * Rh // R))),
                       h_pts.Ns)
            who = f", object {i + 1}/{len(receivers)}" if len(receivers) > 1 else ""
            # the maps keep the island and margin where the bake has one (HorizonMap.direct)
            keep = margin if len(mg[0]) else 0
            # (open: [0, 0]); H[2:] the open bands inside the intervals (a window's sky)
            H = np.zeros((4, A, h_pts.size), np.float16)
            # the footprints' upper edges and their spreads, kept apart from the centres'
            # edges until the map is made (which texels vary is read from the centres)
            fph = (_Footprints(A, h_pts.size) if h_pts.footprint is not None and with_spread
                   else None)
            found = np.zeros(h_pts.size, bool)
            rest = np.arange(h_pts.size)
            picked = (horizon_trial.pick(h_smp.texel, h_smp.resolution, smp.texel, R,
                                         seed=settings.seed) if trial_ok else None)
            trial, decided, counts = None, None, []
            if picked is not None:       # the map on sampled tiles first (horizon_trial)
                h_rows, t_rows = picked
                H_t, figs = yield from _find(occluder, h_pts.subset(h_rows), A,
                                             "horizon trial", who, step + S - 1, total)
                H[:, :, h_rows] = H_t
                counts.append((len(h_rows), figs))
                found[h_rows] = True
                edges.append((yield from _footprints(occluder, h_smp, h_pts, H, fph, found, A,
                                                     who, step + S - 1, total)))
                rest = np.setdiff1d(rest, h_rows, assume_unique=True)
                if fph is not None:       # the footprints' edges for the trial's map ...
                    fph.swap(H)
                # (the tiles' crossings: searched again with the whole map, where the bands
                # may be gone; their figures are the whole map's, the time is the horizons')
                sample = hmap.from_points(H, smp.texel, R, pts.Ns, mg, coarse=low,
                                          spread=None if fph is None else fph.spread,
                                          margin_texels=keep,
                                          cross=(yield from _crossings(
                                              occluder, h_pts, H, [], who, step + S - 1,
                                              total, rows=h_rows)))
                if fph is not None:       # ... and the centres' back (the rest reads them)
                    fph.swap(H)
                trial = _trial(occluder, sample, store, pts.subset(t_rows),
                               smp.texel[t_rows], Dh, settings)
                trial.update(tiles_texels=int(len(h_rows)), texels=int(len(t_rows)),
                             of_texels=int(smp.size))
                decided = horizon_trial.decide(trial["horizon"], trial["transport"])
                trial["decided"] = decided or "whole map and check"
            if decided != "transport":
                # the open bands sought for the rest only where the trial's map found and
                # kept them (on the gallery's mutual shadows they cost 46 % more horizon
                # time and helped nothing)
                bands = trial is None or trial.get("open_bands", {"kept": False})["kept"]
                if not bands:     # (none on the tiles either: a map is banded whole or not)
                    H[2:, :, h_rows] = 0.0
                H_r, figs = yield from _find(occluder, h_pts if len(rest) == h_pts.size
                                             else h_pts.subset(rest), A,
                                             "horizons", who, step + S - 1, total, bands)
                H[:, :, rest] = H_r
                counts.append((len(rest), figs))
                found[rest] = True
                edges.append((yield from _footprints(occluder, h_smp, h_pts, H, fph, found, A,
                                                     who, step + S - 1, total)))
                if fph is not None:        # the footprints' edges for the map
                    fph.swap(H)
            skipped += sum(f["skipped"] for _, f in counts)
            searched += sum(f["searched"] for _, f in counts)
            castable += sum(f["castable"] for _, f in counts)
            gap_rays += sum(f.get("gap_rays", 0) for _, f in counts)
            gap_maps += int(maps_gaps(H))
            cross, b_spread = None, None
            if decided != "transport":      # where a vertical edge crosses each azimuth gap
                cross = yield from _crossings(occluder, h_pts, H, cross_figs, who,
                                              step + S - 1, total)
                # the open bands' edges over the footprints, where the map with them fits
                if fph is not None and maps_gaps(H) and hmap.gpu_bytes(
                        A, R, settings.horizon_resolution, spread=True, gaps=True,
                        cross=True, band_spread=True) <= int(settings.gpu_budget) << 20:
                    b_spread, figs = yield from _band_footprints(occluder, h_smp, h_pts, H, A,
                                                                 who, step + S - 1, total)
                    band_figs.append(figs)
            maps.append(None if decided == "transport" else
                        hmap.from_points(H, smp.texel, R, pts.Ns, mg, coarse=low,
                                         spread=None if fph is None else fph.spread,
                                         margin_texels=keep, cross=cross,
                                         band_spread=b_spread))
            trials.append(trial)
            checks.append(None if decided else _check_rows(occluder, smp, pts, mg, Dh,
                                                           settings))
        horizon_info = {"horizon_azimuths": A, "horizon_resolution": Rh,
                        "horizon_checks": {"directions": Dh, "rows": checks,
                                           "trials": trials},
                        "horizon_seconds": round(time.perf_counter() - t2, 3),
                        "horizon_rays": int(occluder.rays - r2),
                        # scan rays no caster could meet (lt_addon/rays/reach.py): not cast
                        "horizon_rays_skipped": int(skipped),
                        # where each texel's horizon jumps between two azimuths (a
                        # jamb, a post: lt_addon/rays/crossing.py): the (gap, texel) pairs
                        # searched, those whose edge is vertical (kept with a weight, the
                        # others linear), their rays and seconds
                        "horizon_crossings": {
                            k: (round(sum(f[k] for f in cross_figs), 3) if k == "seconds"
                                else int(sum(f[k] for f in cross_figs)))
                            for k in ("pairs", "vertical", "rays", "seconds")},
                        # texels whose edges vary between neighbours: their footprints'
                        # sub-samples found horizons too (the map's spread, horizon_map.py)
                        "horizon_footprints": {
                            "texels": int(sum(e["texels"] for e in edges)),
                            "pairs": int(sum(e["pairs"] for e in edges)),
                            # pairs whose edges vary linearly: the gradient's spread, no rays
                            "smooth_pairs": int(sum(e["smooth_pairs"] for e in edges)),
                            "points": int(sum(e["points"] for e in edges)),
                            "seconds": round(sum(e["seconds"] for e in edges), 3),
                            "lattice": list(HORIZON_LATTICE)} if with_spread else
                        {"left_out": "centre texel sampling" if not footprint else
                         "horizons coarser than the texture" if Rh < R else
                         "the spreads would not fit the GPU budget"},
                        # the open bands inside the intervals (a window's sky): the rays
                        # that sought them and the objects whose horizons hold some (the
                        # viewport's open_bands says whether its map keeps them)
                        "horizon_gaps": {"rays": int(gap_rays),
                                         "objects_found": int(gap_maps)},
                        # their edges over the footprints (where the map keeps bands and
                        # footprints): the pairs, sub-samples and rays, and seconds
                        "horizon_band_footprints": {
                            k: (round(sum(f[k] for f in band_figs), 3) if k == "seconds"
                                else int(sum(f[k] for f in band_figs)))
                            for k in ("texels", "pairs", "points", "rays", "seconds")},
                        # scan rays a caster could meet, and those the search cast of them
                        # (lt_addon/rays/horizon.py _search)
                        "horizon_scan_rays": {"castable": int(castable),
                                              "cast": int(searched)}}
    seconds = time.perf_counter() - t0
    rays = occluder.rays
    return {"engine": "rays", "horizon_maps": maps, **horizon_info,
            "seconds": round(seconds, 3), "scene_seconds": round(t_scene, 3),
            "rays": int(rays), "rays_per_second": round(rays / max(seconds - t_scene, 1e-9)),
            "casters": int(n_casters), "caster_triangles": int(len(T)),
            "texels": [int(smp.size) for smp, _ in receivers],
            # texels touching another object's surface: a contact ray each per lit direction
            "contact_texels": int(touching),
            # each texel's footprint (lt_addon/rays/footprint.py): texel-directions refined
            # (where a shadow edge or a thin triangle passes) and the rays they cast, and the
            # jitter box of this Blender in texels
            "texel_sampling": "footprint" if footprint else "centre",
            **({"footprint_refined": [int(p.footprint.refined) for _, p in receivers],
                "footprint_rays": int(sum(p.footprint.rays for _, p in receivers)),
                # thin smooth texels away from shadow edges: their mean normal, no rays
                "footprint_linear": [int(p.footprint.linear) for _, p in receivers],
                "footprint_box": float(receivers[0][1].footprint.box),
                "footprint_thin_texels": [int(len(p.footprint.thin())) for _, p in receivers]}
               if footprint else {}),
            "margin_texels": margin, "threads": occluder.threads,
            "directions_per_call": chunk}


#: Pairs whose linear edges :func:`_footprints` takes at a time (about 100 bytes each).
SMOOTH_PAIRS = 1 << 18
#: Memory for the footprints' sub-samples and their pairs at a time (a part's texels: at most
#: all their azimuths' pairs, 64 bytes each with their working arrays; 1k texels at 128
#: azimuths).
FOOTPRINT_BYTES = 64 << 20


class _Footprints:
    """The footprints' upper edges ``hi`` and spreads ``spread`` (A, P) float16 (radians, as
    the horizons are kept) of one object's horizon points, and which (azimuth, point) pairs
    have them (``done`` (A, P))."""

    def __init__(self, A: int, P: int):
        self.hi = np.zeros((A, P), np.float16)
        self.spread = np.zeros((A, P), np.float16)
        self.done = np.zeros((A, P), bool)

    def swap(self, H):
        """Exchange the footprints' upper edges with ``H``'s (2, A, P) where they are held,
        in place: the map takes the footprints', and a second swap gives the centres' back
        (no copy of ``H``: 0.5 GB at 1024^2 and 128 azimuths)."""
        d = self.done
        centre = H[1][d]
        H[1][d] = self.hi[d]
        self.hi[d] = centre


def _footprints(occluder, smp, pts, H, fph, found, A: int, who: str, step: int, total: int):
    """Generator: the footprints of the (azimuth, point) pairs whose edges vary between
    neighbours among the points ``found`` (:func:`...lt_addon.transport.horizon_map.
    varying_pairs`, of the centres' horizons ``H`` (2, A, P), the terminator's edges left out)
    and that ``fph`` (:class:`_Footprints`) does not hold yet: the horizons of their texels'
    sub-samples (:data:`...lt_addon.rays.footprint.HORIZON_LATTICE`) along those azimuths
    alone, searched between the texel's and its neighbours' edges (:func:`...lt_addon.rays.
    horizon.iter_pair_edges`), give the pairs' upper edges' means and spreads
    (:func:`...lt_addon.transport.horizon_map.pair_edges`), into ``fph``; where the edges vary
    linearly, the gradient's spread (:func:`...lt_addon.transport.horizon_map.
    smooth_spreads`). A pair's footprint depends on it alone, so a bake that finds its
    horizons in two goes (the trial on sampled tiles, then the rest) gets the same map as one
    go. Returns ``{"texels", "pairs", "points", "smooth_pairs", "seconds"}``; nothing where
    ``fph`` is None."""
    t0 = time.perf_counter()
    if fph is None or pts.footprint is None:
        return {"texels": 0, "pairs": 0, "points": 0, "smooth_pairs": 0, "seconds": 0.0}
    nb = hmap.neighbours(smp.texel, smp.resolution)
    # only points whose neighbours are all found: their pairs and brackets are final
    ready = hmap.surrounded(nb, found)
    want = hmap.varying_pairs(H, smp.texel, smp.resolution, found, normals=pts.Ns) & ~fph.done
    want &= ready[None, :]
    # where the edges vary linearly across the texel, their spread is the gradient's (no rays);
    # a block of texels at a time (the pairs' gathers of five edges are ~100 bytes a pair)
    n_smooth = 0
    block = max(1, SMOOTH_PAIRS // A)
    for b0 in range(0, want.shape[1], block):
        sa_, st_ = np.nonzero(want[:, b0:b0 + block])
        st_ += b0
        smooth, s_spread = hmap.smooth_spreads(H, nb, sa_, st_, pts.footprint.box)
        a_s, t_s = sa_[smooth], st_[smooth]
        fph.hi[a_s, t_s] = H[1, a_s, t_s]
        fph.spread[a_s, t_s] = s_spread[smooth]
        fph.done[a_s, t_s] = True
        want[a_s, t_s] = False
        n_smooth += len(a_s)
    texels = np.nonzero(want.any(axis=0))[0]
    points = pairs = 0
    for j, parts, idx, sub, weight, centre_w, fa, fk, c, group, rows in _footprint_parts(
            pts, texels, want, A):
        points += sub.size
        pairs += len(fa)
        label = "horizon footprints" + (f" (part {j + 1}/{parts})" if parts > 1 else "")
        # each sub-sample's edge between its texel's and the neighbours' (bracketed search)
        lo_b, hi_b = hmap.brackets(H, nb, fa, idx[fk])
        gen = horizon.iter_pair_edges(occluder, sub, A, np.repeat(fa, c), rows,
                                      np.repeat(lo_b, c), np.repeat(hi_b, c))
        m = len(rows)
        lo_s, hi_s = yield from _progress(
            gen, m, lambda done: f"{label} {100 * done // max(m, 1)} %{who}", step, total)
        t = idx[fk]
        mean, spread = hmap.pair_edges(H[0, fa, t], H[1, fa, t], lo_s, hi_s, group,
                                       weight[rows], centre_w[fk])
        fph.hi[fa, t] = mean
        fph.spread[fa, t] = spread
        fph.done[fa, t] = True
    return {"texels": int(len(texels)), "pairs": int(pairs), "points": int(points),
            "smooth_pairs": int(n_smooth), "seconds": time.perf_counter() - t0}


def _progress(gen, n: int, text, step: int, total: int):
    """Generator: run ``gen`` (yielding the units done of ``n``), yielding Progress with
    ``text(done)`` every n / 16 units (a yield lets the bake be cancelled); returns ``gen``'s
    value."""
    said = 0
    while True:
        try:
            done = next(gen)
        except StopIteration as stop:
            return stop.value
        if done - said >= max(1, n // 16) or done == n:   # (blocks of several units)
            said = done
            yield Progress(step, total, text(done))


def maps_gaps(H) -> bool:
    """Whether horizons ``H`` (4, A, P) hold an open band inside some interval."""
    return bool((H[3] > H[2]).any())


def _find(occluder, pts, A: int, label: str, who: str, step: int, total: int,
          gaps: bool = True):
    """Generator: the horizons (4, A, P) of ``pts`` (:func:`...rays.horizon.iter_horizons`,
    with the open bands inside the intervals; ``gaps`` False: none sought, ``[0, 0]``),
    yielding Progress every A / 16 azimuths as "<label> k/A azimuths<who>" (the ETA reads
    "horizons k/A azimuths, object i/n": :func:`...lt_addon.transport.estimate.
    estimated_elapsed`); returns ``(H, figures)``."""
    if not gaps:
        H, figures = yield from _progress(horizon.iter_horizons(occluder, pts, A), A,
                                          lambda done: f"{label} {done}/{A} azimuths{who}",
                                          step, total)
        return np.concatenate([H, np.zeros_like(H)]), figures
    return (yield from _progress(horizon.iter_horizons(occluder, pts, A, gaps=True), A,
                                 lambda done: f"{label} {done}/{A} azimuths{who}", step, total))


def _disc_mean(occluder, pts, d, settings):
    """(P,) the mean of hard suns by rays over the preview sun's disc around ``d``: the held-out
    check's reference."""
    disc = _disc(d, np.radians(settings.sun_angle) / 2, HELDOUT_DISC)
    return direct_rows(occluder, pts, disc).mean(0)


def _check_rows(occluder, smp, pts, margin, directions, settings):
    """The held-out check's reference (n, R*R) (:func:`_disc_mean` per direction), margins
    filled."""
    R = smp.resolution
    dst, op = margin
    rows = np.zeros((len(directions), R * R), np.float32)
    for j, d in enumerate(directions):
        inside = _disc_mean(occluder, pts, d, settings)
        rows[j, smp.texel] = inside
        if dst.size:
            rows[j, dst] = op @ inside
    return rows


def _trial(occluder, sample, store, pts, texels, directions, settings) -> dict:
    """The held-out check on the trial's texels (:mod:`...lt_addon.transport.horizon_trial`):
    the map ``sample`` (its sampled tiles found) and T (the rows just written to ``store``)
    against :func:`_disc_mean` of points ``pts`` at ``texels`` (flat)."""
    refs = [_disc_mean(occluder, pts, d, settings) for d in directions]
    got = [hmap.heldout_errors(m, store, directions, refs, settings.sun_angle,
                               settings.kernel, texels=texels)
           for m in ((sample, sample.without_bands()) if sample.gaps else (sample,))]
    # the open bands kept only where they help (as the whole map's check keeps them)
    return bundle.choose_bands(*got) if sample.gaps else got[0]
