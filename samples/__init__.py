"""Deterministic sample-scene builders (bpy), one per paper scene.

Each builder fills an existing ``bpy.types.Scene`` (so the CLI can write a fresh .blend and the
panel operator can add a scene to the open file) and returns a small dict describing it.
The catalogue below is importable without bpy (the CLI's ``--help`` does not start Blender);
the builders import bpy only when :func:`build` runs.
"""

from __future__ import annotations

#: Sample scenes and their one-line descriptions (shown by the CLI and the panel).
DESCRIPTIONS = {
    "bumps": "tileable patch of spherical bumps and dents (Ashikhmin & Shirley 2002)",
    "noise": "tileable Perlin-noise height field (Ashikhmin & Shirley 2002)",
    "statue": "Suzanne on a ground plane: strong self-shadowing",
    "room": "open box room with red/green/white walls and a box: colour bleeding",
}
SCENES = tuple(DESCRIPTIONS)
SIZES = ("test", "demo")


def _builders() -> dict:
    import bpy  # noqa: F401  (bmesh and mathutils import only after bpy)

    from .objects import build_room, build_statue
    from .patches import build_bumps, build_noise

    return {"bumps": build_bumps, "noise": build_noise, "statue": build_statue, "room": build_room}


def build(name: str, scene, size: str = "test") -> dict:
    """Build sample ``name`` into ``scene`` at ``size``; records name and size on the scene.

    Returns a dict with ``relight_object`` (name of the object to relight) and ``frame``
    (``"tangent"`` for tileable patches, ``"world"`` for object scenes).
    """
    if name not in DESCRIPTIONS:
        raise ValueError(f"unknown sample scene {name!r}; choose one of {', '.join(SCENES)}")
    if size not in SIZES:
        raise ValueError(f"unknown size {size!r}; choose one of {', '.join(SIZES)}")
    info = _builders()[name](scene, size)
    scene["relight_sample"] = name
    scene["relight_sample_size"] = size
    return info
