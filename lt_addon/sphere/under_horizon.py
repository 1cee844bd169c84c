"""Directions just under the horizon, for the part of a soft sun's disc below it (bpy-free).

A Sun lamp 3 degrees high and 10 degrees wide reaches 2 degrees under the horizon. Cycles lights
a wall, a slope or a post from that part of the disc wherever its rays pass the ground's edge;
a transport texture whose directions stop at the horizon counts it dark (on the gallery's fence
and scanned Suzanne a 10-degree Sun 3 degrees high was 0.100 from Cycles for that alone,
docs/bench/2026-12-gallery.md). :func:`with_under` adds the set's own directions of the band
``0 < elevation < depth``, mirrored under the horizon: the same density the set has just above
it, so the relight's interpolation (:func:`..transport.texture.sun_weights`) spans the horizon
as it spans any other band. A floor's texels are dark from all of them (the cosine is negative)
and cost no ray.

They serve a sun's disc only: an environment relight weighs directions above the horizon
(:func:`..transport.texture.environment_weights`), as it did before they were added, so each
added direction carries its mirror's solid angle for the record and nothing sums over it.
"""

from __future__ import annotations

import numpy as np

from .directions import DirectionSet

#: How far under the horizon T's directions reach by default (degrees): a 10-degree Sun's
#: radius, the widest Sun of the gallery's (issue 55) and a common soft one.
UNDER_DEG = 5.0
#: The deepest they go for a wider bake Sun (degrees): the horizon scan's own floor
#: (``lt_addon/rays/horizon.py``, ``BELOW``).
UNDER_MAX_DEG = 10.0


def depth_for(sun_angle_deg: float, asked: float = -1.0) -> float:
    """Degrees under the horizon a bake needs: ``asked`` (the bake's *Under the Horizon*) when
    it is 0 or more, else the radius of its Sun (``sun_angle_deg`` wide), at least
    :data:`UNDER_DEG` (the viewport's Sun may be widened after the bake); at most
    :data:`UNDER_MAX_DEG`."""
    if asked is not None and asked >= 0:
        return float(min(asked, UNDER_MAX_DEG))
    a = float(sun_angle_deg) if np.isfinite(sun_angle_deg) and sun_angle_deg > 0 else 0.0
    return float(min(max(UNDER_DEG, a / 2.0), UNDER_MAX_DEG))


def with_under(base: DirectionSet, depth_deg: float) -> DirectionSet:
    """``base`` (upper hemisphere) with its directions of elevation in ``(0, depth_deg)``
    mirrored under the horizon, put FIRST (a sun path's directions stay the set's last rows,
    where :func:`..sun_path.with_path` put them). Kind ``custom``; ``params`` keep ``base``'s
    and add ``under_directions`` and ``under_horizon_deg``. ``depth_deg <= 0`` or a set that
    already reaches under the horizon returns ``base`` unchanged."""
    d = np.asarray(base.directions, np.float64)
    if depth_deg <= 0 or np.any(d[:, 2] < 0.0):
        return base
    band = (d[:, 2] > 0.0) & (d[:, 2] < np.sin(np.radians(float(depth_deg))))
    if not band.any():
        return base
    under = d[band] * np.array([1.0, 1.0, -1.0])
    params = dict(base.params)
    if base.kind != "custom":
        params = {"base": base.spec, **params}
    params.update(under_directions=int(band.sum()), under_horizon_deg=float(depth_deg))
    return DirectionSet(np.concatenate([under, d]),
                        np.concatenate([base.solid_angles[band], base.solid_angles]),
                        "custom", params)


def under_count(dset: DirectionSet) -> int:
    """How many of ``dset``'s directions lie under the horizon (the first rows)."""
    return int((np.asarray(dset.directions)[:, 2] < 0.0).sum())
