"""What a transport-texture bake's settings cost in memory: the viewport's GPU bytes and the
bake's peak RAM (bpy-free logic over the settings; the estimate and the bake's up-front check
both read it)."""

from __future__ import annotations

from ...lt_addon.transport import horizon_map as hmap


def viewport_gpu(settings, dset, n_objects: int, most: bool = False) -> tuple:
    """(the viewport auto would show, the GPU bytes of its images for all objects, whether the
    block fit is timed in for objects whose horizons auto does not show). With ``most``, the
    bytes are the larger of the horizons' and of what auto shows where it rejects them (the
    statue at 2048^2: its ground the horizons, 70 MiB; the statue blocks, 410 MiB)."""
    from ...lt_addon.transport import sparse_tables as sp
    from .ray_direct import horizon_count, horizon_spread

    k = settings.components or 48
    P = settings.resolution ** 2
    try:
        viewport, _ = sp.choose_viewport(settings.viewport, dset.size, settings.resolution,
                                         budget_mib=settings.gpu_budget,
                                         table_size=settings.table_size)
    except ValueError:
        viewport = "pca"
    A = horizon_count(settings)     # (0 under auto when the map would not fit the budget)
    # both timed: the block fit runs only where auto then finds T closer than the horizons
    blocks_if_not_horizons = bool(A) and viewport == "blocks" and settings.viewport == "auto"
    horizons = A and settings.direct != "cycles"
    if horizons and not most:
        # rays bake the map; auto shows it where the held-out check finds it closer than T
        return "horizon", int(n_objects * hmap.gpu_bytes(
            A, settings.resolution, settings.horizon_resolution,
            spread=horizon_spread(settings))), blocks_if_not_horizons
    if viewport == "transport":
        gpu = n_objects * sp.atlas_layout_bytes(dset.size, settings.resolution)[1]
    elif viewport == "blocks":   # the block size is chosen after the bake: at most this
        from ...lt_addon.transport import block_viewport as bv

        gpu = n_objects * max(bv.gpu_bytes(settings.resolution, B, kb, settings.table_size)
                              ["total_bytes"] for B, kb in bv.candidates(
                                  settings.resolution, settings.table_size,
                                  settings.gpu_budget << 20))
    else:   # eigen-textures in half floats, three per image, uploaded as RGBA
        gpu = n_objects * (-(-k // 3)) * 4 * P * 2
    if horizons:   # (most)
        gpu = max(gpu, n_objects * hmap.gpu_bytes(A, settings.resolution,
                                                  settings.horizon_resolution,
                                                  spread=horizon_spread(settings)))
    return viewport, int(gpu), blocks_if_not_horizons


def memory_bytes(settings, dset, n_objects: int) -> tuple:
    """(peak bytes above the start, the stage it is in) of a bake
    (:mod:`...lt_addon.transport.bake_memory`); the preview's images count twice the GPU bytes
    of the largest viewport auto may show, and the PCA's eigen atlas when it fits the budget
    (it is written then)."""
    from ...lt_addon.transport import bake_memory as bm

    preview_gpu_bytes = viewport_gpu(settings, dset, n_objects, most=True)[1]

    gathered = settings.bounces != 0 and settings.indirect == "gather"   # (-1: the scene's)
    pts = n_objects * settings.indirect_resolution ** 2 if gathered else 0
    k = settings.components or bm.MAX_COMPONENTS
    pca_atlas = (-(-k // 3) + 1) * settings.resolution ** 2 * 8
    if pca_atlas <= settings.gpu_budget << 20:
        preview_gpu_bytes += n_objects * pca_atlas
    return bm.peak_bytes(settings.resolution, n_objects, settings.components, pts,
                         settings.indirect_rays, preview_gpu_bytes, dset.size)
