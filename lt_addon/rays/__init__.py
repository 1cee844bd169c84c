"""Ray-traced direct transport (bpy-free): the texels' shading points, Cycles' rules for a shadow
ray's origin, and batched occlusion rays through Embree (``embreex``).

One Cycles bake call per sun direction costs a whole scene sync and BVH build (61-77 ms at 256^2,
measured 2026-12); the direct light of a hard sun is only visibility x cosine, which rays give for
thousands of directions in the time of a few calls. The bpy layer (``operators/base/ray_scene.py``)
feeds these modules arrays: world-space triangles of every shadow caster, and each receiver's
evaluated mesh with its UV map.

* :mod:`.texels` -- which triangle and which barycentric point each texel samples, as Blender's bake
  rasterizes UV triangles, and Blender's Extend margin beyond UV islands;
* :mod:`.shading` -- shading points (P, Ng, N) and the shadow-ray origins of Cycles' kernel
  (``kernel/light/sample.h``: the shadow-terminator geometry offset, self-intersection);
* :mod:`.engine` -- the occlusion-ray engine (Embree when its wheel is installed);
* :mod:`.direct` -- ``T[s, p]`` for a direction set, in the units of the Cycles bake it replaces.
"""
