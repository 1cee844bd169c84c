"""Distributed transport bakes on a real local Dask cluster of 2 worker processes (issue 15).

The reference is the same command without workers and without the chunk cache: the distributed
T must equal it bit for bit (1 spp, fixed seed; each chunk's directions baked by the same Cycles
calls), also when a worker process is killed in the middle of the bake (Dask reruns its chunk on
the replacement worker).
"""

import os
import signal
import subprocess
import time

import numpy as np
import pytest
from relight_cli import BIN, assert_refused, make_scene, relight

# the direct stage as Cycles calls: what a farm distributes (rays bake it locally in seconds)
TINY = ["--object", "Bumps", "--directions", "hemi:400", "--resolution", "16", "--bounces",
        "0", "--model", "none", "--no-compare", "--direct", "cycles"]


@pytest.fixture(scope="module")
def blend(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dist")
    path = folder / "b.blend"
    make_scene("bumps", path)
    r = relight("bake-textures", path, *TINY, "--no-resume", "--out", folder / "ref")
    assert r.returncode == 0, r.stderr[-2000:]
    return path, np.load(folder / "ref" / "Bumps_transport_texture.npy")


def _same_bits(a, b):
    return a.shape == b.shape and np.array_equal(a.view(np.uint16), b.view(np.uint16))


# The tests that start a cluster are slow on purpose (6-12 s each): 2 worker processes import
# bpy and open the .blend, which is what they prove works.
def test_two_local_workers_bake_the_same_bits_as_one_process(blend, tmp_path):
    path, ref = blend
    r = relight("bake-textures", path, *TINY, "--workers", "2", "--out", tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    import json

    rep = json.loads((tmp_path / "Bumps_texture_report.json").read_text())
    dist = rep["distributed"]
    # 400 directions and the 35 of their band under 5 degrees mirrored under the horizon
    assert dist["chunks"] == rep["chunks_total"] == 28 and rep["chunks_reused"] == 0
    assert len(dist["workers"]) == 2 and dist["file_loads"] == 2   # each worker opened it once
    assert dist["cycles_threads_per_worker"] == max(1, os.cpu_count() // 2)
    # each worker baked on the bake's device (the CPU: the tests set RELIGHT_DEVICE=cpu), and
    # the report says which
    assert sorted(dist["worker_devices"]) == sorted(str(w) for w in dist["workers"])
    assert all(d.startswith("CPU") for d in dist["worker_devices"].values())
    assert rep["device"]["device"] == "CPU"
    assert "distributed: 28 chunks on 2 worker processes" in r.stdout
    assert _same_bits(np.load(tmp_path / "Bumps_transport_texture.npy"), ref)
    assert ".relight_cache" not in os.listdir(tmp_path)


def test_a_worker_killed_mid_bake_is_replaced_and_the_result_is_unchanged(blend, tmp_path):
    import psutil

    path, ref = blend
    proc = subprocess.Popen([str(BIN / "relight"), "bake-textures", str(path), *TINY,
                             "--workers", "2", "--out", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed = None
    deadline = time.monotonic() + 300
    while killed is None and time.monotonic() < deadline and proc.poll() is None:
        if list(tmp_path.glob(".relight_cache/Bumps/*/direct_*.npy")):
            workers = [c for c in psutil.Process(proc.pid).children(recursive=True)
                       if "spawn_main" in " ".join(c.cmdline())
                       and "resource_tracker" not in " ".join(c.cmdline())]
            if workers:
                killed = workers[0].pid
                os.kill(killed, signal.SIGKILL)
        time.sleep(0.02)
    out, err = proc.communicate(timeout=600)
    assert killed is not None, "the bake finished before a worker could be killed"
    assert proc.returncode == 0, err[-3000:]
    assert _same_bits(np.load(tmp_path / "Bumps_transport_texture.npy"), ref)


def test_unreachable_scheduler_and_conflicting_options_exit_2(blend, tmp_path):
    path, _ = blend
    # 1 s instead of the default 10 to wait for the scheduler: nothing listens on port 9
    assert_refused(tmp_path, "cannot reach the Dask scheduler at tcp://127.0.0.1:9",
                   "bake-textures", path, *TINY, "--scheduler", "tcp://127.0.0.1:9",
                   "--connect-timeout", "1", "--out", tmp_path / "o")
    assert_refused(tmp_path, "--connect-timeout must be > 0", "bake-textures", path, *TINY,
                   "--scheduler", "tcp://127.0.0.1:9", "--connect-timeout", "0",
                   "--out", tmp_path / "o")
    assert_refused(tmp_path, "drop --no-resume", "bake-textures", path, *TINY, "--workers", "2",
                   "--no-resume", "--out", tmp_path / "o")
    assert_refused(tmp_path, "drop --no-resume", "bake-textures", path, "--object", "Bumps",
                   "--method", "lobes", "--workers", "2", "--no-resume", "--out", tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_a_worker_refuses_a_scene_that_is_not_the_one_being_baked(blend, tmp_path):
    """The worker compares its file's cache key with the coordinator's: an unsaved change (here
    a key for another scene) is one clear error, never a chunk of the wrong scene."""
    from dataclasses import asdict

    from relightable_textures.operators.farm import distributed
    from relightable_textures.operators.bakes.texture_transport import TransportTextureSettings

    path, _ = blend
    s = asdict(TransportTextureSettings(directions="hemi:400", resolution=16, bounces=0,
                                        model="none"))
    with pytest.raises(distributed.DistributedError, match="not the scene being baked"):
        distributed.bake_chunk(str(path), ["Bumps"], s, 0, 16, str(tmp_path),
                               {"scene": {"objects": {}}})
    assert not list(tmp_path.iterdir())


def test_the_flamenco_job_type_emits_chunk_commands_that_bake_the_same_bits(tmp_path):
    """The farm path without a farm: our Flamenco job type (tools/flamenco) is compiled by
    node with the Manager's task-authoring calls recorded as data (Flamenco itself is not run
    here); every command it emits -- `blender -b FILE --command relight <args>` -- is run with
    <args> through the real console script: the chunk tasks fill the cache (a repeated chunk is
    not baked twice), the final task reuses every chunk, and T equals a one-process bake's."""
    import json
    import pathlib
    import shutil

    node = shutil.which("node")
    assert node, "node is needed to compile the Flamenco job type"
    root = pathlib.Path(__file__).resolve().parents[2]
    blend = tmp_path / "b.blend"
    make_scene("bumps", blend)
    settings = {"objects": "Bumps", "preset": "draft", "directions": "hemi:48",
                "resolution": 16, "force": False, "output_dir": str(tmp_path / "farm"),
                "blendfile": str(blend)}
    r = subprocess.run([node, str(pathlib.Path(__file__).with_name("flamenco_compile.js")),
                        str(root / "tools" / "flamenco" / "relight_transport_bake.js"),
                        json.dumps(settings)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    compiled = json.loads(r.stdout)
    tasks = compiled["tasks"]
    # 48 directions and the 4 under the horizon (its own count: a chunk left out would be
    # baked by the final task, on one machine)
    assert [t["name"] for t in tasks] == [f"relight-chunk-{k}" for k in range(4)] + [
        "relight-fit-and-write"]
    assert tasks[-1]["deps"] == [f"relight-chunk-{k}" for k in range(4)]
    for t in tasks:
        (cmd,) = t["commands"]
        p = cmd["params"]
        assert cmd["name"] == "blender-render" and p["blendfile"] == str(blend)
        assert p["args"][:2] == ["--command", "relight"]
        r = relight(*p["args"][2:])
        assert r.returncode == 0, (p["args"], r.stderr[-2000:])
        if t["name"] == "relight-chunk-1":           # a requeued task: nothing baked again
            again = relight(*p["args"][2:])
            assert again.returncode == 0 and "already in" in again.stdout
    rep = json.loads((tmp_path / "farm" / "Bumps_texture_report.json").read_text())
    # the chunk tasks baked every direction; the final task gathers the indirect light by rays
    # over them (no Cycles chunks: the steerable term's 9 lights were chunks)
    assert rep["direct_chunks"] == rep["chunks_reused"] == 4 and rep["indirect_chunks"] == 0
    assert rep["indirect"]["method"] == "gathered"
    ref = tmp_path / "ref"
    args = [a if a != str(tmp_path / "farm") else str(ref) for a in tasks[-1]["commands"][0]
            ["params"]["args"][2:]]
    assert relight(*args, "--no-resume").returncode == 0
    assert _same_bits(np.load(tmp_path / "farm" / "Bumps_transport_texture.npy"),
                      np.load(ref / "Bumps_transport_texture.npy"))


def test_vertex_transport_bakes_distribute_and_resume_bit_for_bit(tmp_path):
    """`bake-transport --direct cycles --workers 2` gives the one-process samples bit for bit;
    an in-process bake cancelled after its first chunk keeps it, and the rerun reuses it (same
    T). (By rays, the default, the bake takes no Cycles call per direction to distribute.)"""
    import json

    blend = tmp_path / "s.blend"
    make_scene("statue", blend)
    args = ["bake-transport", blend, "--object", "Statue", "--directions", "cube:6",
            "--direct", "cycles"]
    assert relight(*args, "--no-resume", "--out", tmp_path / "ref").returncode == 0
    r = relight(*args, "--workers", "2", "--out", tmp_path / "dist")
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "dist" / "Statue_transport.json").read_text())
    assert rep["chunks_total"] == 14 and rep["distributed"]["chunks"] == 14   # 216 / 16
    assert "distributed: 14 chunks on 2 worker processes" in r.stdout
    ref = np.load(tmp_path / "ref" / "Statue_transport_samples.npy")
    assert _same_bits(np.load(tmp_path / "dist" / "Statue_transport_samples.npy"), ref)
    assert ".relight_cache" not in os.listdir(tmp_path / "dist")

    import bpy

    from relightable_textures.operators.bakes import transport_bake as tb
    from relightable_textures.operators.base.jobs import run

    bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
    obj, scene = bpy.data.objects["Statue"], bpy.context.scene
    s = tb.TransportSettings(directions="cube:6", direct="cycles")
    out = tmp_path / "resume"
    gen = tb.transport_job(scene, obj, s, str(out), preview=False)
    for _ in range(20):                       # directions 1..20: chunk 0 finished
        next(gen)
    gen.close()
    assert os.listdir(out) == [".relight_cache"]
    again = run(tb.transport_job(scene, obj, s, str(out), preview=False))
    assert again.report["chunks_reused"] == 1 and again.report["chunks_total"] == 14
    assert _same_bits(np.load(out / "Statue_transport_samples.npy"), ref)
    assert ".relight_cache" not in os.listdir(out)


def test_a_vertex_bake_by_rays_says_it_left_the_workers_idle(tmp_path):
    """By rays the whole per-vertex bake runs in this process: `--workers` is not silently
    ignored -- one warning line, the report says so, and T is the one-process rays' T."""
    import json

    blend = tmp_path / "s.blend"
    make_scene("statue", blend)
    args = ["bake-transport", blend, "--object", "Statue", "--directions", "cube:2"]
    assert relight(*args, "--out", tmp_path / "ref").returncode == 0
    r = relight(*args, "--workers", "1", "--out", tmp_path / "dist")
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "dist" / "Statue_transport.json").read_text())
    assert rep["direct"]["engine"] == "rays"
    assert "Dask workers were not used" in rep["direct"]["workers_unused"]
    assert r.stderr.count("relight: warning: the Dask workers were not used") == 1
    ref = np.load(tmp_path / "ref" / "Statue_transport_samples.npy")
    assert _same_bits(np.load(tmp_path / "dist" / "Statue_transport_samples.npy"), ref)


@pytest.mark.parametrize("bounce_bake", ["rays", "cycles"])
def test_material_bakes_distribute_and_resume_bit_for_bit(tmp_path, bounce_bake):
    """`bake-materials --workers 2` gives the one-process tensors bit for bit (every term is a
    chunk: direct, and with rays the gather of each block of ray origins, with Cycles one
    bounce per region, the two-bounce references and ordered pairs); an in-process bake
    cancelled part way keeps its finished chunks, a rerun reuses them and gives the same
    tensors, and a change to the scene gives another key (the stale chunks go)."""
    import json

    import bpy

    from relightable_textures.lt_addon.transport import ptt
    from relightable_textures.operators.bakes import material_bake as mb
    from relightable_textures.operators.base.jobs import run

    blend = tmp_path / "room.blend"
    make_scene("room", blend)
    objects, regions = ["Floor", "Box"], ["RedMaterial", "GreenMaterial"]
    args = ["bake-materials", blend, "--object", "Floor", "--object", "Box", "--region",
            "RedMaterial", "--region", "GreenMaterial", "--directions", "hemi:40",
            "--one-bounce-directions", "hemi:20", "--two-bounce-directions", "hemi:4",
            "--samples", "8", "--bounce-bake", bounce_bake,
            # rays make the direct term with rays, Cycles its 40 directions with Cycles
            "--direct", "auto" if bounce_bake == "rays" else "cycles"]
    r = relight(*args, "--no-resume", "--out", tmp_path / "ref")
    assert r.returncode == 0, r.stderr[-2000:]
    ref = ptt.TransferTensors.load(str(tmp_path / "ref" / "Floor_materials.npz"))

    def same(t):
        if not all(np.array_equal(getattr(t, k).view(np.uint8), getattr(ref, k).view(np.uint8))
                   for k in ("direct", "one", "two")):
            return False
        if bounce_bake == "cycles":
            return t.receiver_transfer is None
        m, n = t.receiver_transfer.matrix, ref.receiver_transfer.matrix
        return (np.array_equal(m.data.view(np.uint8), n.data.view(np.uint8))
                and np.array_equal(m.indices, n.indices) and np.array_equal(m.indptr, n.indptr))

    r = relight(*args, "--workers", "2", "--out", tmp_path / "dist")
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "dist" / "Floor_materials.json").read_text())
    # with rays, Cycles' check of the direct term (8 of the 40 directions, 1 chunk) and 378
    # ray origins / 256 -> 2 gather chunks; with Cycles 40/16 -> 3 direct chunks, 3 regions x
    # 2 one-bounce chunks, 3 references + 9 ordered pairs
    chunks = 1 + 2 if bounce_bake == "rays" else 3 + 6 + 3 + 9
    assert rep["chunks_total"] == rep["distributed"]["chunks"] == chunks
    assert rep["chunks_reused"] == 0 and len(rep["distributed"]["workers"]) == 2
    assert f"distributed: {chunks} chunks on 2 worker processes" in r.stdout
    assert same(ptt.TransferTensors.load(str(tmp_path / "dist" / "Floor_materials.npz")))
    assert ".relight_cache" not in os.listdir(tmp_path / "dist")

    bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
    scene, objs = bpy.context.scene, [bpy.data.objects[n] for n in objects]
    s = mb.MaterialBakeSettings(regions=regions, directions=("hemi:40", "hemi:20", "hemi:4"),
                                samples=8, bounce_bake=bounce_bake,
                                direct="auto" if bounce_bake == "rays" else "cycles")
    out = tmp_path / "resume"
    gen = mb.materials_job(scene, objs, s, str(out))
    # rays: the 2 gather chunks (rays first, before the gates) and the direct light's check
    # (8 Cycles calls), stopped in the direct light by rays (not kept: seconds);
    # Cycles: the 3 direct chunks (40 directions) and the first one-bounce chunk (16)
    if bounce_bake == "rays":
        while "direct by rays" not in next(gen).message:
            pass
    else:
        for _ in range(60):
            next(gen)
    gen.close()
    kept = 3 if bounce_bake == "rays" else 4
    assert os.listdir(out) == [".relight_cache"]
    (folder,) = (out / ".relight_cache").iterdir()
    assert folder.name == "Floor_materials" and len(list(folder.glob("*/*_0*.npy"))) == kept
    again = run(mb.materials_job(scene, objs, s, str(out)))
    assert again.report["chunks_reused"] == kept and again.report["chunks_total"] == chunks
    assert same(again.tensors) and ".relight_cache" not in os.listdir(out)

    gen = mb.materials_job(scene, objs, s, str(out))
    for _ in range(5):   # a chunk or more is kept (with rays the whole bake yields 18 times)
        next(gen)
    gen.close()
    old = mb.material_chunk_cache(scene, objs, s, str(out)).folder
    bpy.data.objects["Box"].location.x += 0.1    # the scene changed: another key
    bpy.context.view_layer.update()
    new = mb.material_chunk_cache(scene, objs, s, str(out))
    assert new.folder != old and not os.path.exists(old)


def _exr_channels(path):
    from relightable_textures.lt_addon.io.exrio import read_exr

    return read_exr(str(path))[0]


def _same_exr(a, b):
    ca, cb = _exr_channels(a), _exr_channels(b)
    return ca.keys() == cb.keys() and all(
        np.array_equal(np.asarray(ca[k]).view(np.uint8), np.asarray(cb[k]).view(np.uint8))
        for k in ca)


def test_basis_light_stages_distribute_and_resume_bit_for_bit(blend, tmp_path):
    """Every basis light is a chunk too: the transport method's indirect stage (9 lights of the
    order-3 basis) and the lobes method's K = order^2 lights are baked on 2 workers bit for bit
    as in one process; a lobes bake cancelled after 4 lights keeps them and its rerun reuses
    them (same texture), and an indirect stage cancelled part way resumes the same way."""
    import json

    import bpy

    from relightable_textures.operators.bakes import steerable_bake as sb, texture_transport as tx
    from relightable_textures.operators.base.jobs import run

    path, _ = blend
    args = ["bake-textures", path, "--object", "Bumps", "--directions", "hemi:48",
            "--resolution", "16", "--bounces", "1", "--indirect", "steerable",
            "--indirect-samples", "4", "--indirect-resolution", "8", "--model", "none",
            "--no-compare", "--direct", "cycles"]
    assert relight(*args, "--no-resume", "--out", tmp_path / "ref").returncode == 0
    r = relight(*args, "--workers", "2", "--out", tmp_path / "dist")
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "dist" / "Bumps_texture_report.json").read_text())
    assert rep["direct_chunks"] == 4 and rep["indirect_chunks"] == 9    # 48 + 4 under the horizon
    assert rep["chunks_total"] == rep["distributed"]["chunks"] == 13
    assert _same_exr(tmp_path / "dist" / "Bumps_indirect.exr",
                     tmp_path / "ref" / "Bumps_indirect.exr")
    assert _same_bits(np.load(tmp_path / "dist" / "Bumps_transport_texture.npy"),
                      np.load(tmp_path / "ref" / "Bumps_transport_texture.npy"))

    lobes = ["bake-textures", path, "--object", "Bumps", "--method", "lobes", "--order", "3",
             "--resolution", "16", "--samples", "4", "--bounces", "1", "--no-compare"]
    assert relight(*lobes, "--no-resume", "--out", tmp_path / "lref").returncode == 0
    r = relight(*lobes, "--workers", "2", "--out", tmp_path / "ldist")
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "ldist" / "Bumps_steerable.json").read_text())
    assert rep["chunks_total"] == rep["distributed"]["chunks"] == 9
    assert _same_exr(tmp_path / "ldist" / "Bumps_steerable.exr",
                     tmp_path / "lref" / "Bumps_steerable.exr")
    assert ".relight_cache" not in os.listdir(tmp_path / "ldist")

    bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
    scene, obj = bpy.context.scene, bpy.data.objects["Bumps"]
    s = sb.TextureBakeSettings(order=3, resolution=16, samples=4, bounces=1)
    run(sb.lobes_job(scene, obj, s, str(tmp_path / "lhere"), preview=False, resume=False))
    out = tmp_path / "lresume"
    gen = sb.lobes_job(scene, obj, s, str(out), preview=False)
    for _ in range(4):
        next(gen)
    gen.close()
    assert len(list(out.glob(".relight_cache/Bumps_lobes/*/light_*.npy"))) == 4
    again = run(sb.lobes_job(scene, obj, s, str(out), preview=False))
    assert again.report["chunks_reused"] == 4 and again.report["chunks_total"] == 9
    assert _same_exr(out / "Bumps_steerable.exr", tmp_path / "lhere" / "Bumps_steerable.exr")
    assert ".relight_cache" not in os.listdir(out)

    ts = tx.TransportTextureSettings(directions="hemi:48", resolution=16, bounces=1,
                                     indirect="steerable", indirect_samples=4,
                                     indirect_resolution=8, model="none", direct="cycles")
    out = tmp_path / "tresume"
    gen = tx.bake_transport_textures(scene, [obj], ts, str(out))
    for step in gen:                   # the albedo, 52 directions, then indirect lights
        if step.message.startswith("indirect bake 5/"):
            break
    gen.close()
    nested = list(out.glob(".relight_cache/Bumps/indirect/*/light_*.npy"))
    assert len(nested) == 5 and len(list(out.glob(".relight_cache/Bumps/*/direct_*.npy"))) == 4
    res = run(tx.bake_transport_textures(scene, [obj], ts, str(out)))
    assert res.chunks["chunks_reused"] == 4 + 5 and res.chunks["chunks_total"] == 13
    tx.write_bake(res, [obj], str(out))
    assert _same_exr(out / "Bumps_indirect.exr", tmp_path / "ref" / "Bumps_indirect.exr")
    assert ".relight_cache" not in os.listdir(out)
