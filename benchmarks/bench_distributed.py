"""Benchmark (issue 15): what distributing and resuming a transport bake costs and gains.

On the demo ``bumps`` patch with the draft transport settings (400 directions, 128^2, 2 bounces),
in one process (the chunk cache off), then on local Dask clusters of 1, 2 and 4 worker processes
(their Cycles threads: the cores shared out), it prints the wall time of the direct stage and of
the whole bake, the cluster's start-up, the per-chunk figures (wall per chunk, the .blend loads,
Cycles' share), and checks every T against the single-process one bit for bit. Then a cold bake
with the chunk cache, cancelled once the direct stage is done (the indirect bakes started), and
its warm rerun: what resuming saves.

``--bake materials`` does the same for the material bake of ``make demo`` (the demo room, its
five meshes, the red and green walls editable, the default settings: 400 direct directions by
Cycles, the bounces gathered by 512 rays per receiver, per face corner; 25 direct chunks of 16
directions and one gather chunk per 256 receivers): one process, 1/2/4 workers (tensors
checked bit for bit), and a cold bake cancelled once its gather is done (its direct bakes
started) with its warm rerun.

Usage: python benchmarks/bench_distributed.py [--workers 1,2,4] [--size demo|test]
                                              [--bake textures|materials]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", default="1,2,4")
    ap.add_argument("--size", default="demo")
    ap.add_argument("--bake", choices=("textures", "materials"), default="textures")
    args = ap.parse_args(argv)
    if args.bake == "materials":
        return bench_materials(args)

    import bpy

    from relightable_textures import samples
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    work = tempfile.mkdtemp(prefix="relight-bench-dist-")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    samples.build("bumps", bpy.context.scene, args.size)
    blend = os.path.join(work, "bumps.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    scene, objs = bpy.context.scene, [bpy.data.objects["Bumps"]]
    settings = tx.settings_from_preset("draft")
    print(f"bumps {args.size}, draft: {settings.directions} at {settings.resolution}^2, "
          f"{os.cpu_count()} cores", flush=True)

    def bake(out, **kw):
        t0 = time.perf_counter()
        res = run(tx.bake_transport_textures(scene, objs, settings, os.path.join(work, out),
                                             **kw))
        return res, time.perf_counter() - t0

    ref, single_wall = bake("single", resume=False)
    T_ref = np.load(ref.objects[0].store_path)
    s = ref.seconds
    print(f"one process: direct {s['direct_total']:.1f} s (Cycles {s['direct_cycles']:.1f} s), "
          f"bake {single_wall:.1f} s", flush=True)
    for n in map(int, args.workers.split(",")):
        res, wall, up = _on_local_cluster(n, bake, blend)
        d = res.chunks["distributed"]
        same = np.array_equal(np.load(res.objects[0].store_path).view(np.uint16),
                              T_ref.view(np.uint16))
        per = d["chunk_seconds"]
        print(f"{n} workers ({d['cycles_threads_per_worker']} Cycles threads each): cluster "
              f"start {up:.1f} s; direct {res.seconds['direct_total']:.1f} s "
              f"({d['chunks']} chunks: median {statistics.median(per):.2f} s, max "
              f"{max(per):.2f} s per chunk of 16; Cycles {d['cycles_seconds']:.1f} s summed; "
              f"{d['file_loads']} .blend loads); bake {wall:.1f} s; T identical: {same}",
              flush=True)

    # cold, cancelled after the direct stage, then the warm rerun
    cold = _cancel_at(tx.bake_transport_textures(scene, objs, settings,
                                                 os.path.join(work, "resume")), "indirect")
    res, warm = bake("resume")
    print(f"resume: cold run cancelled at its indirect stage after {cold:.1f} s; the warm rerun "
          f"({res.chunks['chunks_reused']}/{res.chunks['chunks_total']} chunks reused) took "
          f"{warm:.1f} s where the one-process bake took {single_wall:.1f} s", flush=True)


def _on_local_cluster(n: int, bake, blend: str):
    """``bake(out, client=, blend_path=)`` on a new local cluster of ``n`` workers; returns its
    result, its wall seconds and the cluster's start-up seconds."""
    from relightable_textures.operators.farm import distributed

    t0 = time.perf_counter()
    client = distributed.connect(workers=n)
    up = time.perf_counter() - t0
    try:
        res, wall = bake(f"w{n}", client=client, blend_path=blend)
    finally:
        distributed.close(client)
    return res, wall, up


def _cancel_at(gen, prefix: str) -> float:
    """Run the job ``gen`` until a step whose message starts with ``prefix``, then cancel it
    (as Esc does); returns the seconds it ran."""
    t0 = time.perf_counter()
    for step in gen:
        if step.message.startswith(prefix):
            break
    gen.close()
    return time.perf_counter() - t0


def bench_materials(args):
    import bpy

    from relightable_textures import samples
    from relightable_textures.operators.bakes import material_bake as mb
    from relightable_textures.operators.base.jobs import run

    work = tempfile.mkdtemp(prefix="relight-bench-dist-mat-")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    samples.build("room", bpy.context.scene, args.size)
    blend = os.path.join(work, "room.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    scene = bpy.context.scene
    objs = [bpy.data.objects[n] for n in ("Floor", "WallLeft", "WallRight", "WallBack", "Box")]
    settings = mb.MaterialBakeSettings(regions=["RedMaterial", "GreenMaterial"],
                                       domain="CORNER")
    print(f"room {args.size}, material bake as make demo's: {settings.specs()}, bounces by "
          f"{settings.bounce_bake} ({settings.rays} rays), per corner, {os.cpu_count()} cores",
          flush=True)

    def bake(out, **kw):
        t0 = time.perf_counter()
        res = run(mb.materials_job(scene, objs, settings, os.path.join(work, out), **kw))
        return res, time.perf_counter() - t0

    def same(a, b):
        return all(np.array_equal(getattr(a, k).view(np.uint32), getattr(b, k).view(np.uint32))
                   for k in ("direct", "one", "two"))

    ref, single_wall = bake("single", resume=False)
    t = ref.report["timings"]
    print(f"one process: bake {single_wall:.1f} s ({ref.report['bake_calls']} Cycles bakes, "
          f"{ref.report['chunks_total']} chunks; Cycles {t['cycles_seconds']:.1f} s; direct "
          f"{t.get('direct_seconds', 0):.1f} s, bounce rays {t.get('bounce_rays_seconds', 0):.1f}"
          f" s)", flush=True)
    for n in map(int, args.workers.split(",")):
        res, wall, up = _on_local_cluster(n, bake, blend)
        d = res.report["distributed"]
        per = d["chunk_seconds"]
        print(f"{n} workers ({d['cycles_threads_per_worker']} Cycles threads each): cluster "
              f"start {up:.1f} s; on the workers {d['wall_seconds']:.1f} s ({d['chunks']} "
              f"chunks: median {statistics.median(per):.2f} s, max {max(per):.2f} s; Cycles "
              f"{d['cycles_seconds']:.1f} s summed; {d['file_loads']} .blend loads); bake "
              f"{wall:.1f} s; tensors identical: {same(res.tensors, ref.tensors)}", flush=True)

    cold = _cancel_at(mb.materials_job(scene, objs, settings, os.path.join(work, "resume")),
                      "direct")
    res, warm = bake("resume")
    print(f"resume: cold run cancelled once its direct bakes started (the gather done), "
          f"after {cold:.1f} s; the warm "
          f"rerun ({res.report['chunks_reused']}/{res.report['chunks_total']} chunks reused) "
          f"took {warm:.1f} s where the one-process bake took {single_wall:.1f} s; tensors "
          f"identical: {same(res.tensors, ref.tensors)}", flush=True)


if __name__ == "__main__":
    main()
