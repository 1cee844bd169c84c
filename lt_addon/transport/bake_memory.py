"""A transport-texture bake's peak memory, stated before it starts (issue 33; bpy-free).

The bake's stages run one after another. Each holds its own working set on top of what the
earlier ones keep (the albedos, 12 bytes a texel); the bake's peak is the largest stage. What
each stage holds, in bytes, besides :data:`FIXED` (``N``: texels of all objects; ``n``: the largest object's; ``P``:
points of the indirect grid of all objects; ``K``: rays per point; ``k``: the PCA's components
at most, 96 under a ``tol``):

==========  =================================================================  ==============
stage       what it holds                                                      bytes
==========  =================================================================  ==============
albedo      Cycles' colour bake of every object                                ALBEDO x N
direct      every object's shading points and texel samples (169 bytes a       DIRECT x N
            texel, kept for the horizons), one direction's rays and rows
indirect    the gather's hits and sparse bounce matrices, the PCA's images     PER_RAY x P x K
            and their QR (gathered_indirect.indirect_pca; independent of the   + 12 N
            texture's side since its T windows); and T's met columns in        [+ 4 S n]
            float32 (S directions), kept between the PCA's passes when one
            window holds them all (2 S n <= WINDOW_BYTES: at most 128 MiB)
fit         the eigen-textures of every object in float32, one object's        (4 k + 96) N
            stream of T, the block viewport's fit
write       the model file's half-float copy of one object's eigen-textures    (4 k + 96) N
            on top of the fit's; the preview's images in Blender (float32:      + 2 k n
            twice the GPU memory of its half floats)                            + 2 gpu
==========  =================================================================  ==============

T itself is never held: it is streamed to a memory-mapped file whose pages are page cache
(not counted: the kernel drops them under pressure). The figures are the anonymous resident
memory above the level before the bake (what :mod:`..peak_memory` samples).

The constants are the measured bytes per unit rounded up (bench and dates in
docs/bench/2026-transport-log.md, "Memory"): the balanced preset on the bumps demo at 4096^2 (16.8 M
texels) and the statue with its ground at 1024^2, 2 cores, 2026-12-04.
"""

from __future__ import annotations

#: bytes any stage holds whatever the sizes (the ray engine's scene, Cycles' session, NumPy's
#: temporaries): the bumps at 128^2 and 256^2 peaked 127 and 145 MiB above the start
FIXED = 64 << 20
#: bytes per texel of Cycles' colour bake of the albedos (measured 190 at 4096^2)
ALBEDO = 200
#: bytes per texel of the direct stage, rays and horizons (shading points, texel samples, a
#: chunk of directions' rows and rays, the horizon trial and check; above FIXED, measured 290 on
#: the bumps at 512^2 and 4096^2 and 432 on the statue with its ground at 1024^2)
DIRECT = 450
#: bytes per gather ray (the grid's points x rays) of the gathered indirect term: the hits, the
#: bounce matrices, the PCA's images (above FIXED and the albedos; measured 9 on the bumps at
#: 512^2, where many hits share a texel, 31 on the statue at 1024^2, 44 on the bumps at 4096^2,
#: where nearly every hit meets a texel of its own)
PER_RAY = 48
#: bytes per texel held in the fit besides the eigen-textures (the albedo, a stream's chunk, the
#: block viewport's fit where auto makes one; the statue with its ground at 2048^2 held 475 bytes
#: a texel with 96 components, 384 of them the eigen-textures)
HELD = 96
#: the PCA's components at most when a ``tol`` chooses them (texture.fit_texture_pca's max_k)
MAX_COMPONENTS = 96


def stage_bytes(resolution: int, n_objects: int, components: int | None,
                indirect_points: int, indirect_rays: int, preview_gpu_bytes: int = 0,
                directions: int = 0) -> dict:
    """{stage: bytes} of a bake of ``n_objects`` objects at ``resolution`` (texels across, the
    same for all). ``components``: the PCA's (None: a tol chooses, at most
    :data:`MAX_COMPONENTS`); ``indirect_points``: the gather's points of all objects (0: no
    gathered term); ``indirect_rays``: rays per point; ``preview_gpu_bytes``: the GPU memory of
    the images the preview loads, all objects (0: no preview); ``directions``: T's (S; 0: not
    counted)."""
    from .gathered_indirect import WINDOW_BYTES

    n = int(resolution) ** 2
    N = n * int(n_objects)
    k = int(components) if components else MAX_COMPONENTS
    fit = (4 * k + HELD) * N
    S = int(directions)
    window = 4 * S * n if indirect_points and S and 2 * S * n <= WINDOW_BYTES else 0
    stages = {
        "albedo": ALBEDO * N,
        "direct": DIRECT * N,
        "indirect": PER_RAY * int(indirect_points) * int(indirect_rays) + 12 * N + window,
        "fit": fit,
        "write": fit + 2 * k * n + 2 * int(preview_gpu_bytes),
    }
    return {name: FIXED + b for name, b in stages.items()}


def peak_bytes(*args, **kw) -> tuple:
    """(bytes, stage) of the largest stage of :func:`stage_bytes`."""
    stages = stage_bytes(*args, **kw)
    stage = max(stages, key=stages.get)
    return stages[stage], stage
