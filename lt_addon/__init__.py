"""Blender-free core of Relightable Textures: NumPy/SciPy only.

Never import bpy or mathutils here (a test enforces it, in every subpackage). Arrays in,
arrays out. One subpackage per concern, one module per idea:

* ``sphere/``    -- directions on the sphere and hemisphere, direction sets with solid angles,
  and the classic sphere bases (spherical harmonics, Haar wavelets) used as baselines;
* ``steerable/`` -- steerable illumination textures (Ashikhmin & Shirley 2002): the basis
  lights, the sampled basis, calibration, clamping and the baked texture object;
* ``transport/`` -- sampled light transport: direction-sampled transport textures, per-vertex
  eigentransport (Nowrouzezahrai et al. 2008), clustered PCA and its cost theory (Mahajan et
  al. 2007), the transport sidecar format and error curves;
* ``geometry/``  -- height fields of the paper scenes and UV layout checks;
* ``io/``        -- files: atomic writes, OpenEXR with metadata, storage codecs, preview atlases
  and PNG contact sheets;
* ``checks/``    -- reproductions of the papers' numbers with this core (``relight validate``).
"""
