"""Benchmark (issue 13): what one change of the world's lighting costs the transport-texture
preview lit by the World (Texture Light = World), against the issue's 5 ms per change.

Bakes the demo ``bumps`` patch with a transport preset (default balanced: 400 directions, 256^2,
PCA 96, 2 bounces -> steerable indirect of order 3), installs the preview, gives the world a
``--hdri``-sized equirect (a sky with a small bright sun) behind a Mapping node, switches the
preview to the World and times:

* the first update (reads the HDRI's pixels from Blender once);
* ``--changes`` updates through the Environment Rotation property (its update callback: the
  vertex preview's refresh, then the texture previews' coefficients), median and max;
* the same through the world Mapping's Z rotation and the depsgraph handler;
* the parts of one update: weights (sampling the HDRI at the S directions), the two matrix
  products, and writing the constants into the node groups.

Then renders the preview with Cycles at the camera-less top view (render_check) and compares
it with the NumPy relight of the model (relative RMSE), and with T itself, to show the model's
own error under this environment.

Usage: python benchmarks/bench_env_preview.py [--preset balanced] [--hdri 2048] [--changes 40]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests",
                                "blender"))


def sky(width: int) -> np.ndarray:
    """(H, W, 3) bottom row first: a blue-to-white sky, dark ground, a 3-degree sun of 2000x."""
    h = width // 2
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(width) + 0.5) / width
    el = (v - 0.5) * np.pi
    az = (u - 0.5) * 2 * np.pi
    up = np.clip(np.sin(el), 0, None)[:, None]
    img = np.zeros((h, width, 3), np.float32)
    img[..., 0] = 0.3 + 0.5 * (1 - up)
    img[..., 1] = 0.45 + 0.4 * (1 - up)
    img[..., 2] = 0.9 + 0.1 * (1 - up)
    img[el < 0] = 0.05
    d_el, d_az = np.radians(25.0), np.radians(40.0)
    cosang = (np.sin(el)[:, None] * np.sin(d_el)
              + np.cos(el)[:, None] * np.cos(d_el) * np.cos(az[None, :] - d_az))
    img[np.arccos(np.clip(cosang, -1, 1)) < np.radians(1.5)] = 2000.0
    return img


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="balanced")
    ap.add_argument("--hdri", type=int, default=2048, help="HDRI width (height = width / 2)")
    ap.add_argument("--changes", type=int, default=40)
    args = ap.parse_args(argv)

    import bpy

    import relightable_textures
    from relightable_textures import samples
    from relightable_textures.lt_addon.transport import texture as tt
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.preview import transport_preview as tp
    from relightable_textures.operators.base.jobs import run
    from render_check import render_rgb
    from test_texture_transport import _sky_world

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    relightable_textures.register()
    scene = bpy.context.scene
    samples.build("bumps", scene, "demo")
    obj = bpy.data.objects["Bumps"]
    s = tx.settings_from_preset(args.preset, bounces=2)
    out = tempfile.mkdtemp(prefix="bench-env-")
    t0 = time.perf_counter()
    rep = run(tx.bake_job(scene, [obj], s, out, truth=0, compare=False)).reports[0]
    print(f"{args.preset}: {s.directions}, {s.resolution}^2, PCA {rep['model'].get('k')}, "
          f"bake {time.perf_counter() - t0:.1f} s", flush=True)
    env = sky(args.hdri)
    world, mapping = _sky_world(scene, env, 0.0)
    # an HDRI as users have one: an image file, not an edited (dirty) generated image
    from relightable_textures.lt_addon.io import exrio

    hdr = os.path.join(out, "sky.exr")
    exrio.write_exr(hdr, {c: env[..., i] for i, c in enumerate("RGB")}, {}, pixel_type="float")
    tex = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(hdr)
    tex.image.colorspace_settings.name = "Non-Color"
    props = scene.relight
    t0 = time.perf_counter()
    props.texture_light = "WORLD"     # builds the environment groups, first update
    print(f"switch to World (groups built, HDRI {args.hdri}x{args.hdri // 2} read): "
          f"{1e3 * (time.perf_counter() - t0):.1f} ms", flush=True)
    times = []
    for i in range(args.changes):
        t0 = time.perf_counter()
        props.env_rotation = (i * 9.0) % 360.0 - 180.0
        times.append(1e3 * (time.perf_counter() - t0))
    print(f"Environment Rotation change (callback: vertex + texture previews): median "
          f"{statistics.median(times):.2f} ms, max {max(times):.2f} ms over {len(times)}")
    times = []
    for i in range(args.changes):
        mapping.inputs["Rotation"].default_value[2] = np.radians(i * 7.0)
        t0 = time.perf_counter()
        bpy.context.view_layer.update()   # the depsgraph handler runs here
        times.append(1e3 * (time.perf_counter() - t0))
    print(f"world Mapping Z change (depsgraph update + handler): median "
          f"{statistics.median(times):.2f} ms, max {max(times):.2f} ms")
    times = {"update (all parts)": [], "weights": [], "products": [], "write constants": []}
    from relightable_textures.operators.preview.vertex_relight import world_light

    data = tp._env_data(obj)
    env64 = world_light(scene)[0]      # the cached float64 pixels the preview samples
    g = bpy.data.node_groups[f"{tp.ENV_PREFIX} ({obj.name})"]
    gi = bpy.data.node_groups.get(f"{tp.ENV_PREFIX} indirect ({obj.name})")
    for i in range(args.changes):
        t0 = time.perf_counter()
        tp.update_environment_previews(scene)
        t1 = time.perf_counter()
        W = tt.environment_weights(data["directions"], env64, row_order="bottom_first",
                                   rotation_deg=i * 5.0, validate=False)
        t2 = time.perf_counter()
        C = W.T @ data["V"]
        G = W.T @ data["B"] if data["B"] is not None else None
        t3 = time.perf_counter()
        tp.set_env_constants(g, "C", C)
        if gi is not None and G is not None:
            tp.set_env_constants(gi, "G", G)
        t4 = time.perf_counter()
        for k, a, b in (("update (all parts)", t0, t1), ("weights", t1, t2),
                        ("products", t2, t3), ("write constants", t3, t4)):
            times[k].append(1e3 * (b - a))
    for k, v in times.items():
        print(f"  {k}: median {statistics.median(v):.3f} ms, max {max(v):.3f} ms")
    print(f"  constants per change: {len(g[tp.ENV_VALUES])} + "
          f"{len(gi[tp.ENV_VALUES]) if gi else 0} driven floats; S = {len(data['V'])} directions")

    # the picture: Cycles render of the preview vs the NumPy relight (model and T)
    mapping.inputs["Rotation"].default_value[2] = 0.0
    props.env_rotation = 0.0
    tp.update_environment_previews(scene)
    bake, store, _ = tx.load_bake(rep["report"])
    R = store.resolution
    import pathlib

    img = render_rgb(scene, pathlib.Path(out), R)
    scene.world = world
    model = tx.relight_environment(bake, store, env, 0.0, row_order="bottom_first",
                                   source="model")
    full = tx.relight_environment(bake, store, env, 0.0, row_order="bottom_first",
                                  source="transport")

    def rel(a, b):
        return float(np.linalg.norm(np.asarray(a, np.float64) - b) / np.linalg.norm(b))

    print(f"Cycles render of the World-lit preview vs NumPy relight of the model: "
          f"{rel(img, model):.2e} (half-float atlases); model vs T: {rel(model, full):.4f}")
    relightable_textures.unregister()


if __name__ == "__main__":
    main()
