"""Directions along the scene Sun's animated path (issue 32): read from the frames, added to
the bake's set, and what they buy at a low sun -- against Cycles' bake of that sun."""

import math

import numpy as np
import pytest

from relightable_textures import samples
from relightable_textures.lt_addon.sphere.hemisphere import direction_from_az_el


def _animate_sun(scene, frames=(1, 49)):
    """A Sun over a day: azimuth 80 -> 280 degrees, elevation -3 -> 50 -> -3 (keyframes)."""
    import bpy
    from mathutils import Vector

    data = bpy.data.lights.new("DaySun", "SUN")
    sun = bpy.data.objects.new("DaySun", data)
    scene.collection.objects.link(sun)
    scene.frame_start, scene.frame_end = frames
    n = frames[1] - frames[0] + 1
    for i, f in enumerate(range(frames[0], frames[1] + 1)):
        t = i / (n - 1)
        az, el = 80 + 200 * t, -3 + 53 * math.sin(math.pi * t)
        towards = Vector(direction_from_az_el(az, el).tolist())
        sun.rotation_mode = "QUATERNION"
        sun.rotation_quaternion = (-towards).to_track_quat("-Z", "Y")
        sun.keyframe_insert("rotation_quaternion", frame=f)
    return sun


def _low_sun_on_path(scene, spp: int = 1):
    """The bumps test patch under the animated Sun: (object, a hard Sun's direction at 8
    degrees of elevation on the path, Cycles' direct bake of that Sun at 32^2: 1 spp, the
    texel centres, as a centre-texel bake; ``spp`` more, converged over the texels)."""
    from relightable_textures.operators.base.cycles_bake import EnvironmentBake

    samples.build("bumps", scene, "test")
    obj = scene.objects["Bumps"]
    _animate_sun(scene)
    t = math.asin(11 / 53) / math.pi                      # elevation 8 on the rising side
    d = direction_from_az_el(80 + 200 * t, 8.0)
    with EnvironmentBake(scene, [obj], 32, spp, 0, (8, 16), mode="irradiance", seed=0,
                         world_sampling="none", passes="direct") as s:
        truth = s.bake_sun(d, 1.0, 0.0)[..., 0]
    return obj, d, truth


def _settings(**kw):
    from relightable_textures.operators.bakes.texture_transport import TransportTextureSettings

    base = dict(directions="hemi:100:1.5", resolution=32, bounces=0, model="none")
    base.update(kw)
    return TransportTextureSettings(**base)


def test_the_path_is_read_from_the_frames_and_added(fresh_scene):
    from relightable_textures.lt_addon.errors import InputError
    from relightable_textures.lt_addon.sphere.under_horizon import under_count
    from relightable_textures.operators.bakes.texture_transport import resolve_directions

    samples.build("bumps", fresh_scene, "test")
    # the sample scene's own Sun does not move: nothing is added, and +sun-path is refused
    d, info = resolve_directions(fresh_scene, _settings())
    # (and the band under 5 degrees mirrored under the horizon, its first rows)
    assert info is None and d.size == 100 + under_count(d) and under_count(d) > 10
    with pytest.raises(InputError, match="no Sun lamp that moves"):
        resolve_directions(fresh_scene, _settings(directions="hemi:100:1.5+sun-path"))
    fresh_scene.frame_set(7)
    _animate_sun(fresh_scene)
    d, info = resolve_directions(fresh_scene, _settings())
    assert info["object"] == "DaySun" and info["frames"] == [1, 49]
    assert fresh_scene.frame_current == 7                  # the frame is restored
    # the day's arc above the horizon, every half degree (about 200 deg of azimuth at up to
    # 50 deg of elevation: a few hundred directions)
    assert 250 < info["path_directions"] < 600 and d.size == info["base_directions"] + \
        info["path_directions"] + under_count(d)
    assert info["elevation_deg"][0] < 1.0 and info["elevation_deg"][1] == pytest.approx(50, abs=0.5)
    d1, info1 = resolve_directions(fresh_scene, _settings(directions="hemi:100:1.5+sun-path:1"))
    assert info1["path_directions"] < 0.6 * info["path_directions"]
    d0, info0 = resolve_directions(fresh_scene, _settings(sun_path="off"))
    assert info0 is None and d0.size == 100 + under_count(d0)


def test_a_low_sun_on_the_path_relights_closer_to_cycles(fresh_scene, tmp_path):
    """The bake with the path against the bake without, for a hard Sun at 8 degrees of
    elevation on the path, against Cycles' own bake of that Sun of the same kind as T (1 spp,
    the texel centre, direct light). A 64-spp radiance truth judges Cycles' pixel filter as
    much as the directions: measured 0.16 / 0.32 (with / without the path) on 5.0.1 and 0.25 /
    0.28 on 5.3.0, whose bakes filter differently; benchmarks/bench_sun_path.py measures the
    2-degree Sun with bounces."""
    from relightable_textures.operators.bakes.texture_transport import bake_transport_textures
    from relightable_textures.operators.base.jobs import run

    obj, d, truth = _low_sun_on_path(fresh_scene)
    assert (truth == 0).mean() > 0.05                      # long shadows at 8 degrees
    errs = {}
    for mode in ("auto", "off"):
        # (texel centres: the truth is Cycles' first sample; footprints: test_footprint.py)
        res = run(bake_transport_textures(fresh_scene, [obj], _settings(
            sun_path=mode, texel_sampling="centre"), str(tmp_path / mode), resume=False))
        store = res.objects[0].store
        errs[mode] = float(np.linalg.norm(store.sun(d, 0.0) - truth) / np.linalg.norm(truth))
        store.abort()
    size = res.direct["direction_set"]["size"]                     # "off": the set alone
    assert size == 100 + res.direct["direction_set"]["under_horizon"]["directions"]
    # on the path a baked direction lies within 0.07 degrees: nearly Cycles' own bake; off it,
    # the nearest of 100 directions are degrees away and their shadows blend
    assert errs["auto"] < 0.05 and errs["off"] > 4 * errs["auto"], errs


def test_an_animated_sun_raises_the_horizons_to_the_texture_side(fresh_scene, tmp_path):
    """With the Sun's path in the set, the bake makes its horizons at the texture's side and at
    least PATH_AZIMUTHS azimuths, whatever coarser ones the settings (a preset's) ask, and says
    so; those horizons relight a hard Sun at 8 degrees on the path closer to Cycles' converged
    bake of it (256 spp) than the coarse ones: measured 2026-12-06, 0.078 against 0.245 (bpy
    5.0.1), 0.141 against 0.303 (5.3.0); without the footprints' edge spreads the fine map was
    0.167 / 0.253 (against Cycles' 1-spp bake, the texel centres, 0.101 on both).
    benchmarks/bench_sun_path.py measures the 2-degree Sun with bounces at 256^2
    (docs/bench/2026-transport-log.md)."""
    from relightable_textures.lt_addon.transport import horizon_map as hmap
    from relightable_textures.lt_addon.transport.bundle import direct_summary
    from relightable_textures.operators.bakes.texture_transport import bake_transport_textures
    from relightable_textures.operators.base.jobs import run

    # converged: the map at the texture's side models the texels' footprints (a 1-spp truth
    # is the texel centres)
    obj, d, truth = _low_sun_on_path(fresh_scene, spp=256)
    coarse = dict(model="pca", viewport="horizon", horizon_azimuths=32, horizon_resolution=16)
    errs, maps = {}, {}
    for mode in ("auto", "off"):
        res = run(bake_transport_textures(fresh_scene, [obj], _settings(sun_path=mode, **coarse),
                                          str(tmp_path / mode), resume=False))
        b = res.objects[0]
        maps[mode] = (b.found_horizon.azimuths, b.found_horizon.horizon_resolution,
                      res.direct.get("horizons_raised"), direct_summary(res.direct, 100))
        errs[mode] = float(np.linalg.norm(b.found_horizon.direct(d, 0.0) - truth)
                           / np.linalg.norm(truth))
        b.store.abort()
    assert maps["off"][:3] == (32, 16, None)
    assert maps["auto"][:2] == (hmap.PATH_AZIMUTHS, 32)
    assert maps["auto"][2]["from"] == {"azimuths": 32, "side": 16}
    assert "raised from 32 at 16^2 for the animated Sun" in maps["auto"][3]
    assert errs["auto"] < 0.7 * errs["off"], errs


def test_the_target_error_pilot_keeps_an_asked_sun_path(fresh_scene, tmp_path):
    """--directions hemi:N:P+sun-path:STEP with --target-error: the pilot's counts keep the
    power and the path (split as the spec is parsed, not by counting colons)."""
    from relightable_textures.operators.bakes.texture_transport import pilot
    from relightable_textures.operators.base.jobs import run

    samples.build("bumps", fresh_scene, "test")
    obj = fresh_scene.objects["Bumps"]
    _animate_sun(fresh_scene)
    te = run(pilot(fresh_scene, [obj], _settings(directions="hemi:100:1.3+sun-path:2"), 0.99,
                   str(tmp_path), resolution=16, truth_samples=8))
    assert te["tried"][0]["directions"] == "hemi:64:1.3+sun-path:2" and te["met_in_pilot"]
