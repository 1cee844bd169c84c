"""The scene's animated Sun (bpy): its direction over the frame range, for directions along its
path (:mod:`...lt_addon.sphere.sun_path`).

Keyframes, drivers, constraints and handlers (the Sun Position add-on moves its Sun from a frame
handler) all show in the Sun's world matrix after ``scene.frame_set``, so the path is read by
stepping through the frames -- at most :data:`MAX_SAMPLES` of them, the path between samples
following great circles -- and the current frame is restored.
"""

from __future__ import annotations

import numpy as np

#: Frames sampled at most over the scene's range.
MAX_SAMPLES = 400
#: A Sun whose direction moves less than this over the range (degrees) is not animated.
STILL_DEG = 0.01


def scene_suns(scene) -> list:
    """Sun lamps that render, in name order."""
    return sorted((o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"
                   and not o.hide_render), key=lambda o: o.name)


def sun_path(scene):
    """The first animated Sun's path: ``{"object", "frames": [first, last], "samples",
    "directions": (F, 3) towards the sun}``, or None when no Sun moves."""
    suns = scene_suns(scene)
    if not suns:
        return None
    first, last = int(scene.frame_start), int(scene.frame_end)
    frames = np.unique(np.round(np.linspace(first, last, min(MAX_SAMPLES, last - first + 1)))
                       .astype(int)) if last > first else np.array([first])
    current, sub = scene.frame_current, scene.frame_subframe
    paths = {o.name: [] for o in suns}
    try:
        for f in frames:
            scene.frame_set(int(f))
            for o in suns:
                m = np.array(o.matrix_world, np.float64)[:3, :3]
                z = m[:, 2]                              # the lamp shines along its local -Z
                paths[o.name].append(z / max(np.linalg.norm(z), 1e-30))
    finally:
        scene.frame_set(current, subframe=sub)
    for o in suns:
        d = np.array(paths[o.name])
        if len(d) > 1 and np.degrees(np.arccos(np.clip((d @ d[0]).min(), -1, 1))) > STILL_DEG:
            return {"object": o.name, "frames": [first, last], "samples": int(len(d)),
                    "directions": d}
    return None


#: The Sun size the bake takes where the scene has no Sun (degrees; the presets' measured
#: figures are for 2 and 10 degrees).
DEFAULT_SUN_ANGLE = 2.0


def scene_bounces(scene) -> int:
    """The diffuse bounces the scene's own render takes (Render > Light Paths): Diffuse, capped
    by Total (Cycles stops a path at whichever it reaches first; a diffuse-only bake's paths
    are diffuse)."""
    cycles = getattr(scene, "cycles", None)
    if cycles is None:
        return 4
    return int(max(0, min(int(cycles.diffuse_bounces), int(cycles.max_bounces))))


def scene_sun_angle(scene) -> float | None:
    """The angular diameter (degrees) of the scene's first rendered Sun (Blender's default
    0.526), or None without a Sun."""
    import math

    suns = scene_suns(scene)
    return math.degrees(float(suns[0].data.angle)) if suns else None
