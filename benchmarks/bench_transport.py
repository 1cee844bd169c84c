"""Benchmark: per-vertex transport + eigentransport -- bake speed, error vs d against SH and
Haar, Cycles ground truth per d, storage, and the viewport update cost at ~40k vertices.

Prints figures (not a test) and writes JSON. Usage:
    python benchmarks/bench_transport.py [--scenes statue,room] [--size demo|test]
        [--directions cube:16] [--json out/bench/transport.json]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OBJECTS = {"statue": "Statue", "room": "Floor"}  # the room's floor receives colour bleeding


def bench_scene(name: str, size: str, spec: str, bounces: int) -> dict:
    import bpy

    from relightable_textures import samples
    from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
    from relightable_textures.lt_addon.transport.eigentransport import fit_eigentransport, project_environment
    from relightable_textures.lt_addon.transport.error import error_curves, sun_sky_environment
    from relightable_textures.operators.bakes import transport_bake as tb
    from relightable_textures.operators.base.jobs import run

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build(name, scene, size)
    obj = bpy.data.objects[OBJECTS[name]]
    ds = parse_direction_spec(spec)
    res = run(tb.bake_transport(scene, obj, ds.directions, bounces=bounces))
    V, S = res.transport.shape
    T = res.transport.astype(np.float64)
    suns = ([0.4, -0.3, 0.8], [-0.7, 0.2, 0.4], [0.1, 0.8, 0.3], [0.0, 0.0, 1.0])
    envs = [sun_sky_environment(64, d, row_order="bottom_first", sun_radius_deg=8.0,
                                sun_radiance=500.0) for d in suns]
    lw = np.stack([project_environment(e, ds.directions, ds.solid_angles,
                                       row_order="bottom_first") for e in envs])
    counts = [c for c in (4, 9, 16, 25, 36, 49, 64, 100) if c <= min(V, S)]
    curves = error_curves(T, ds, lw, counts=counts)
    model = fit_eigentransport(T, energy=0.999)
    truth = tb.truth_errors(scene, obj, model, ds, envs[0], bounces, 256,
                            ds_for=tuple(counts), transport=res.transport)
    return {"scene": f"{name}-{size}", "object": obj.name, "vertices": V, "directions": S,
            "direction_set": spec, "bounces": bounces,
            "bake_seconds": round(res.total_seconds, 3),
            "cycles_seconds": round(res.cycles_seconds, 3),
            "seconds_per_direction": round(res.cycles_seconds / S, 5),
            "directions_per_second": round(S / res.total_seconds, 2),
            "d_at_99.9_percent": model.d, "storage_bytes": model.storage_bytes(),
            "curves": curves, "ground_truth": truth}


def bench_update(n_vertices: int = 40000, d: int = 48, spec: str = "cube:16",
                 repeats: int = 30) -> dict:
    """Viewport update cost: environment projection + exact shading + attribute write."""
    import bmesh
    import bpy

    from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
    from relightable_textures.lt_addon.transport.eigentransport import Eigentransport
    from relightable_textures.lt_addon.transport.error import sun_sky_environment
    from relightable_textures.operators.preview import vertex_relight as vr
    from relightable_textures.operators.base.meshes import object_from_bmesh

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bm = bmesh.new()
    rings = int(round(np.sqrt(n_vertices / 4)))
    bmesh.ops.create_uvsphere(bm, u_segments=4 * rings, v_segments=rings, radius=1.0)
    obj = object_from_bmesh("Ball", bm, bpy.context.scene.collection)
    V = len(obj.data.vertices)
    ds = parse_direction_spec(spec)
    rng = np.random.default_rng(0)
    basis, _ = np.linalg.qr(rng.normal(size=(ds.size, d)))
    model = Eigentransport(rng.uniform(0, 1, ds.size), basis.T, rng.normal(size=(V, d)),
                           np.ones(d), float(d))
    env = sun_sky_environment(64, [0.4, -0.3, 0.8], row_order="bottom_first")
    times = {"project_ms": [], "shade_ms": [], "write_ms": []}
    for _ in range(repeats):
        t0 = time.perf_counter()
        from relightable_textures.lt_addon.transport.eigentransport import project_environment

        lw = project_environment(env, ds.directions, ds.solid_angles, row_order="bottom_first")
        t1 = time.perf_counter()
        values = model.shade(lw)
        t2 = time.perf_counter()
        vr.write_shading(obj, values)
        t3 = time.perf_counter()
        times["project_ms"].append(1e3 * (t1 - t0))
        times["shade_ms"].append(1e3 * (t2 - t1))
        times["write_ms"].append(1e3 * (t3 - t2))
    med = {k: round(float(np.median(v[3:])), 3) for k, v in times.items()}
    med["total_ms"] = round(sum(med.values()), 3)
    return {"vertices": V, "d": d, "directions": ds.size, **med}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="statue,room")
    parser.add_argument("--size", default="demo", choices=["test", "demo"])
    parser.add_argument("--directions", default="cube:16")
    parser.add_argument("--bounces", type=int, default=0)
    parser.add_argument("--json", default=os.path.join(ROOT, "out", "bench", "transport.json"))
    args = parser.parse_args()
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="relight-bench-"))
    os.makedirs(os.path.dirname(args.json), exist_ok=True)
    out = {"scenes": [], "update": None}
    for name in args.scenes.split(","):
        row = bench_scene(name, args.size, args.directions, args.bounces)
        out["scenes"].append(row)
        print(f"\n== {row['scene']} ({row['object']}): {row['vertices']} vertices x "
              f"{row['directions']} directions ({row['direction_set']}), bounces {row['bounces']}")
        print(f"   bake {row['bake_seconds']:.2f} s ({row['seconds_per_direction'] * 1e3:.1f} ms "
              f"per direction in Cycles, {row['directions_per_second']:.1f} directions/s); "
              f"d at 99.9% energy = {row['d_at_99.9_percent']}")
        c = row["curves"]
        print("   coeffs | transport rel. error: eigen   SH     Haar | shading (max over 4 "
              "sun+sky): eigen   SH     Haar")
        for i, n in enumerate(c["counts"]):
            def get(basis, key):
                b = c.get(basis, {})
                return f"{b[key][i]:.4f}" if key in b else "  -   "
            print(f"   {n:6d} |                {get('eigentransport', 'transport_rel')} "
                  f"{get('sh', 'transport_rel')} {get('haar', 'transport_rel')} |"
                  f"                          {get('eigentransport', 'shading_rel_max')} "
                  f"{get('sh', 'shading_rel_max')} {get('haar', 'shading_rel_max')}")
        g = row["ground_truth"]
        print(f"   vs Cycles vertex bake ({g['truth_samples']} spp): all directions "
              f"{g['all_directions_rel_rms_error']:.4f}; " + ", ".join(
                  f"d={r['d']}: {r['rel_rms_error']:.4f}" for r in g["per_d"]))
        sb = row["storage_bytes"]
        print(f"   storage at d={row['d_at_99.9_percent']}: coefficients {sb['coefficients']} B, "
              f"sidecar arrays {sb['sidecar']} B, paper's 4d(v+1) = {sb['paper_runtime']} B")
    out["update"] = bench_update()
    u = out["update"]
    print(f"\n== viewport update at {u['vertices']} vertices, d = {u['d']}, {u['directions']} "
          f"directions: project {u['project_ms']} ms + shade {u['shade_ms']} ms + attribute "
          f"write {u['write_ms']} ms = {u['total_ms']} ms (median)")
    from relightable_textures.lt_addon.io import atomic

    atomic.write_json(args.json, out)
    print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
