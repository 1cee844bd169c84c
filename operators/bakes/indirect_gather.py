"""The transport bake's indirect light gathered by rays over T's own directions (bpy layer).

Feeds :mod:`...lt_addon.transport.gathered_indirect` the scene's arrays -- every receiver's
triangles with its UVs, every other shadow caster's, the gather points of the indirect grid --
and stores the PCA over directions as one :class:`...lt_addon.transport.gathered_texture.
GatheredIndirect` per object. Measured against the order-3 steerable bake (Cycles, 9 calls) by
``benchmarks/bench_indirect_gather.py``: lower error at every light measured, in 1/2 to 1/4 of
its time (docs/bench/2026-transport-log.md).

What it leaves out (the report's ``indirect`` figures count them): a ray that meets a
receiver's back side or a non-receiver adds nothing (Cycles would shade that surface); gather
points use the mesh's shading normals, not a normal map's.
"""

from __future__ import annotations

import time

import numpy as np

from ...lt_addon.progress import Progress
from ...lt_addon.rays import engine
from ...lt_addon.rays.texels import extend_margin
from ...lt_addon.transport import gathered_indirect as gi
from ...lt_addon.transport.gathered_texture import GatheredIndirect
from ..base import ray_scene


#: The largest share of the gather's surface hits on objects that are not baked before the bake
#: takes Cycles' steerable term instead (the statue demo baked without its ground: the gathered
#: term held 15-41 % of Cycles' indirect light; baked together: within 1.2 %).
MAX_OTHER = 0.05


def receiver_geometry(objects, depsgraph):
    """World triangles of what diffuse bounce rays meet, as Cycles has them: the receivers
    (each with its UVs) and every other rendered object, each unless its Ray Visibility >
    Diffuse is off (``visible_diffuse``: the rays pass through it, as Cycles' do, though it
    may cast shadows; an object that casts no shadow still reflects): (V (N, 3), T (M, 3),
    receiver (M,) index or -1, uv (M, 3, 2)). A receiver's triangles wind counter-clockwise
    seen from outside in world space -- a mirrored object's (negative scale) reversed -- so the
    gather's front-side test (the winding's normal) is Cycles' own."""
    names = [o.name for o in objects]
    V, T, recv, UV, offset = [], [], [], [], 0
    for i, o in enumerate(objects):
        if not getattr(o, "visible_diffuse", True):
            continue      # gathers light at its points, met by no bounce ray
        m = ray_scene.mesh_arrays(o, depsgraph)
        if m.uv is None:
            raise ValueError(f"{o.name} has no UV map")
        tri, loops = m.tri, m.loops
        if m.mirrored:   # its world winding turns inward: reversed, the triangles' normals
            tri, loops = tri[:, ::-1], loops[:, ::-1]   # face out as Cycles' flipped Ng does
        V.append(m.co)
        T.append(tri + offset)
        recv.append(np.full(len(tri), i))
        UV.append(m.uv[loops.ravel()].reshape(-1, 3, 2))
        offset += len(m.co)
    co, tri, _ = ray_scene.casters(depsgraph, exclude_names=names, ray="diffuse")   # the rest
    V.append(co)
    T.append(tri + offset)
    recv.append(np.full(len(tri), -1))
    UV.append(np.zeros((len(tri), 3, 2)))
    return np.concatenate(V), np.concatenate(T), np.concatenate(recv), np.concatenate(UV)


class StackedRows:
    """The objects' T rows side by side, read by chunks of directions (half floats on disk):
    what :func:`...lt_addon.transport.gathered_indirect.indirect_pca` reads."""

    def __init__(self, arrays):
        self.arrays = arrays
        self.shape = (arrays[0].shape[0], sum(a.shape[1] for a in arrays))

    def __getitem__(self, rows):
        return np.concatenate([np.asarray(a[rows]) for a in self.arrays], axis=1)

    def columns(self, lo: int, hi: int) -> np.ndarray:
        """All rows at the stacked columns ``[lo, hi)`` (S, hi - lo), in the stores' dtype."""
        parts, start = [], 0
        for a in self.arrays:
            n = a.shape[1]
            if lo < start + n and hi > start:
                parts.append(np.asarray(a[:, max(lo - start, 0):min(hi - start, n)]))
            start += n
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)


def gather_points(scene, objects, resolution: int):
    """The gather's scene: (V, T, receiver, uv, [(TexelSamples, ShadingPoints)] at the indirect
    grid per object), read once within the render settings."""
    with ray_scene.RenderGeometry(scene) as dg:
        V, T, recv, UV = receiver_geometry(objects, dg)
        grids = [ray_scene.receiver_points(o, dg, resolution, None) for o in objects]
    return V, T, recv, UV, grids


def stack_points(grids, resolution: int):
    """The objects' gather points stacked: (per object a (R*R,) map texel -> stacked point, -1
    outside its islands; origins pushed off the surface, shading and geometric normals, each
    (P, 3); the stacked offsets, len(grids) + 1)."""
    RI = int(resolution)
    gmaps, origins, normals, geo, offs = [], [], [], [], [0]
    for smp, pts in grids:
        m = np.full(RI * RI, -1, np.int64)
        m[smp.texel] = offs[-1] + np.arange(smp.size)
        gmaps.append(m)
        origins.append(pts.compact()["P_up"])      # the point pushed off its plane
        normals.append(pts.Ns)
        geo.append(pts.Ng)
        offs.append(offs[-1] + smp.size)
    return (gmaps, np.concatenate(origins), np.concatenate(normals), np.concatenate(geo),
            offs)


#: The gathered term's PCA keeps at least the asked components, and more -- up to
#: :data:`COMPONENT_GROWTH` times as many -- while the sketch's singular values past them hold
#: more than this share of its RMS (:func:`...gathered_indirect.indirect_pca`). Measured
#: 2026-12-07 on the gallery's interior (a room lit through a window; 1024-spp truths; the
#: whole picture's error were the direct light exact): 16 components 0.041-0.087 over its 18
#: cells, 32: 0.029-0.052, 48: 0.024-0.050, 64: 0.021-0.048 (512 rays instead of 128 changed
#: nothing: the count is the limit, not the rays). The tails at 16 components in a 64-component
#: sketch: the room 0.22, its box 0.11, the statue demo 0.062 and its ground 0.075, the bumps
#: 0.024 -- so the statue, its ground and the bumps keep 16.
COMPONENT_TAIL = 0.08
COMPONENT_GROWTH = 4
#: ... and only while the atlas of component images the viewport holds (a padded tile per
#: component, half-float RGBA on the GPU: :func:`image_bytes`) stays within this: at a 128^2
#: grid it never binds, at 512^2 it stops at 56, at 1024^2 there is no growth from 16
GROWTH_BYTES = 128 << 20


def image_bytes(components: int, grid: int) -> int:
    """GPU bytes of the gathered term's component atlas: ``components`` tiles of ``grid``^2
    (one RGB image each, padded, :func:`...lt_addon.io.atlas.atlas_layout`), 8 bytes a texel."""
    from ...lt_addon.io.atlas import atlas_layout

    lay = atlas_layout(int(components), int(grid))
    return lay["width"] * lay["height"] * 8


def growth_cap(components: int, grid: int) -> int:
    """The most components the gathered term's PCA may grow to: up to
    :data:`COMPONENT_GROWTH` times the asked count while :func:`image_bytes` stays within
    :data:`GROWTH_BYTES`, never fewer than asked."""
    k = COMPONENT_GROWTH * int(components)
    while k > int(components) and image_bytes(k, grid) > GROWTH_BYTES:
        k -= 1
    return max(int(components), k)


def bake(scene, objects, arrays, albedos, dset, *, resolution: int, bounces: int,
         rays: int, components: int, seed: int = 1, margin: int = 4,
         step: int = 0, total: int = 1, max_other: float = MAX_OTHER):
    """Generator: the gathered indirect term of every object (yields Progress; returns
    ``([GatheredIndirect per object], figures)``, or ``(None, figures with "why")`` when more
    than ``max_other`` of the rays that met a surface met objects not baked: their reflected
    light is not in any T, so the gathered term would miss it).

    ``arrays``: per object T's rows (S, R*R) (a store's memmap, float16); ``albedos``: per
    object (R, R, 3); ``resolution``: the indirect grid's side; ``margin``: the bake's Extend
    margin in T's texels (filled at the grid's scale, at least one)."""
    t0 = time.perf_counter()
    R = int(round(np.sqrt(arrays[0].shape[1])))
    RI = int(resolution)
    yield Progress(step, total, "indirect light: gather points")
    V, T, recv, UV, grids = gather_points(scene, objects, RI)
    occ = engine.Occluder(V, T)
    gmaps, origins, normals, geo, offs = stack_points(grids, RI)
    t_scene = time.perf_counter() - t0
    yield Progress(step, total, f"indirect light: {rays} rays from {offs[-1]:,} points")
    t0 = time.perf_counter()
    g = gi.gather(occ.nearest, origins, normals, geo, rays, seed, V, T, recv, UV, R,
                  [i * R * R for i in range(len(objects))], RI, gmaps)
    t_rays = time.perf_counter() - t0
    hits = len(g.point) + g.other + g.back
    other = g.other / max(hits, 1)
    if other > max_other:
        return None, {"method": "gathered", **g.figures(), "other_share": round(other, 4),
                      "max_other_share": max_other,
                      "seconds": {"scene": round(t_scene, 3), "rays": round(t_rays, 3)},
                      "why": (f"{100 * other:.0f} % of the gather rays that met a surface met "
                              f"objects that are not baked (over {100 * max_other:.0f} %): the "
                              "gathered light reads only T of the objects baked together, so the "
                              "bake took Cycles' steerable term, which sees every object; bake "
                              "the objects that reflect light onto each other together")}
    yield Progress(step, total, f"indirect light: {bounces} bounce(s), PCA {components}")
    t0 = time.perf_counter()
    alb = np.concatenate([np.asarray(a, np.float32).reshape(-1, 3) for a in albedos])
    rows = StackedRows(arrays)          # read by windows of texel columns (gi.WINDOW_BYTES)
    grown: dict = {}
    Vc, U, _ = gi.indirect_pca(g, rows, alb, bounces=bounces, components=components, seed=seed,
                               tail=COMPONENT_TAIL, most=growth_cap(components, RI),
                               figures=grown)
    t_pca = time.perf_counter() - t0
    centre = ((np.arange(RI) + 0.5) * R / RI).astype(np.int64)
    out = []
    # (points, rays and where they went: over all objects gathered together)
    figures = {"method": "gathered", "rays_per_point": int(rays), "bounces": int(bounces),
               "components": int(Vc.shape[1]), "components_asked": int(components),
               "component_sketches": grown.get("sketches"),
               "component_tail": grown.get("tail"), "resolution": RI, **g.figures(),
               "seconds": {"scene": round(t_scene, 3), "rays": round(t_rays, 3),
                           "pca": round(t_pca, 3)}}
    for i, (smp, _) in enumerate(grids):
        a = np.asarray(albedos[i], np.float32)[centre][:, centre].reshape(-1, 3)[smp.texel]
        dst, op = extend_margin(smp.covered(), max(1, -(-margin * RI // R)))
        imgs = np.zeros((Vc.shape[1], RI * RI, 3), np.float32)
        vals = U[:, :, offs[i]:offs[i + 1]].transpose(0, 2, 1) * a[None]      # (k, P_i, 3)
        imgs[:, smp.texel] = vals
        if dst.size:
            for j in range(len(imgs)):
                imgs[j, dst] = op @ vals[j]
        out.append(GatheredIndirect(
            imgs.reshape(-1, RI, RI, 3), Vc, dset,
            settings={**{k: v for k, v in figures.items() if k != "seconds"},
                      "object": objects[i].name, "object_points": int(smp.size),
                      "objects_gathered_together": len(objects), "seed": int(seed),
                      "mode": "radiance"}))
    return out, figures
