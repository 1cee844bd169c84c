"""Bakes on the device the user chose (operators/base/cycles_device.py), on real Cycles bakes.

These machines have no GPU: what is proven here is the CPU side of every rule, the refusal of
``--device gpu`` before any bake, that the device chosen is what the Cycles session bakes on
(read back during the bake) with the scene's own setting restored, that reports and the CLI say
which device baked, and that chunks of another device are baked again, not mixed in. Each test
reads the GPUs Cycles finds itself (:func:`_gpus`), so on a machine with one it checks the GPU
side of the same rule instead. The GPU bake itself is not run here.
"""

import json
import os
import shutil

import numpy as np
import pytest
from relight_cli import assert_refused, make_scene, our_lines, relight

TINY = ["--object", "Bumps", "--directions", "hemi:32", "--resolution", "8", "--bounces", "0",
        "--model", "none", "--no-compare"]


def _gpus() -> dict:
    """{backend: [device names]} of the GPUs Cycles finds here, read without cycles_device."""
    import bpy

    prefs = bpy.context.preferences.addons["cycles"].preferences
    found = {}
    for backend in ("OPTIX", "CUDA", "HIP", "METAL", "ONEAPI"):
        try:
            names = [d.name for d in prefs.get_devices_for_type(backend) if d.type == backend]
        except Exception:   # a backend this build does not have
            names = []
        if names:
            found[backend] = names
    return found


def test_auto_cpu_and_gpu_resolve_to_what_this_machine_has(fresh_scene):
    from relightable_textures.operators.base import cycles_device as cd

    gpus = _gpus()
    auto = cd.resolve("auto", fresh_scene)   # the bpy module: the first backend Cycles finds
    if gpus:
        assert auto.kind == "GPU" and auto.backend == next(iter(gpus)) and auto.note is None
    else:
        assert (auto.kind, auto.backend, auto.id) == ("CPU", "NONE", "CPU")
        assert auto.note == "no GPU found (OPTIX, CUDA, HIP, METAL, ONEAPI tried)"
        assert auto.report() == {"device": "CPU", "backend": "NONE", "names": [auto.cpu_name],
                                 "choice": "auto", "note": auto.note,
                                 "threads": cd.thread_plan(auto)}
        with pytest.raises(cd.DeviceError, match="--device gpu: Cycles finds no GPU"):
            cd.resolve("gpu", fresh_scene)
    cpu = cd.resolve("cpu", fresh_scene)
    assert (cpu.kind, cpu.note) == ("CPU", None) and cpu.describe().startswith("CPU")
    with pytest.raises(cd.DeviceError, match="device must be one of auto, cpu, gpu"):
        cd.resolve("tpu", fresh_scene)
    # nothing chose a device: a bake driven from a script bakes on the CPU, as it always did
    assert cd.current().kind == "CPU"


def test_the_device_reaches_the_cycles_session_and_the_scene_keeps_its_own(fresh_scene):
    """The user's scene asks for the GPU; the resolved device (the CPU on a machine without one)
    is what Cycles' session has at every step of a real bake, and afterwards the scene says
    GPU again and the preferences' backend is unchanged."""
    import bmesh
    import bpy

    from relightable_textures.operators.base import cycles_device as cd
    from relightable_textures.operators.bakes import transport_bake as tb
    from relightable_textures.operators.base.jobs import run
    from relightable_textures.operators.base.meshes import object_from_bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=8, v_segments=4, radius=1.0)
    obj = object_from_bmesh("Ball", bm, fresh_scene.collection, smooth=True)
    prefs = bpy.context.preferences.addons["cycles"].preferences
    backend = prefs.compute_device_type
    fresh_scene.cycles.device = "GPU"
    device = cd.resolve("auto", fresh_scene)
    seen = []
    dirs = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.7, 0.7]]
    with cd.use(device):
        res = run(tb.bake_transport(fresh_scene, obj, dirs),
                  on_progress=lambda step: seen.append(fresh_scene.cycles.device))
    assert len(seen) >= 3 and set(seen) == {device.kind}, seen
    assert fresh_scene.cycles.device == "GPU" and prefs.compute_device_type == backend
    assert res.transport.shape == (len(obj.data.vertices), 3) and res.bake_calls == 3
    assert cd.current().kind == "CPU"   # use() ended with the bake


def test_cli_device_gpu_without_a_gpu_is_one_line_before_any_bake(tmp_path):
    if _gpus():
        pytest.skip("this machine has a GPU: --device gpu bakes there")
    blend = make_scene("bumps", tmp_path / "b.blend")
    r = assert_refused(tmp_path, "--device gpu: Cycles finds no GPU on this machine",
                       "bake-textures", blend, *TINY, "--device", "gpu", "--out", tmp_path / "o")
    assert not (tmp_path / "o").exists()
    assert not [ln for ln in our_lines(r.stderr)[:-1] if "direction" in ln], r.stderr[-2000:]
    env = dict(os.environ, RELIGHT_DEVICE="tpu")
    assert_refused(tmp_path, "$RELIGHT_DEVICE must be one of auto, cpu, gpu, got 'tpu'",
                   "bake-transport", blend, "--object", "Bumps", "--out", tmp_path / "o",
                   env=env)


def test_cli_says_which_device_baked_and_the_report_records_it(tmp_path):
    blend = make_scene("statue", tmp_path / "s.blend")
    out = tmp_path / "t"
    r = relight("bake-transport", blend, "--object", "Statue", "--directions", "cube:2",
                "--device", "auto", "--out", out)
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((out / "Statue_transport.json").read_text())["device"]
    said = [ln for ln in our_lines(r.stderr) if ln.startswith("bake-transport: baking on ")]
    assert len(said) == 1, r.stderr[-2000:]
    assert rep["choice"] == "auto"
    if _gpus():
        assert rep["device"] == "GPU" and said[0].startswith("bake-transport: baking on GPU")
    else:
        assert rep["device"] == "CPU" and rep["backend"] == "NONE"
        assert said[0].startswith("bake-transport: baking on CPU") and "no GPU found" in said[0]
        assert rep["note"] in said[0]


def test_a_resumed_bake_bakes_another_devices_chunks_again_unless_told_to_mix(tmp_path):
    """A farm task (``relight bake-chunk``, the CPU) bakes chunk 0 into the cache. Left as it
    is, the final bake reuses it; relabelled as a GPU's chunk (its key's device changed, under
    that key's folder, as a GPU bake would have left it), the final bake on the CPU bakes it
    again, says so, and the result is bit for bit the same as the bake that reused it; with
    ``--mix-devices`` it reuses the relabelled chunk and says so."""
    from relightable_textures.lt_addon.io.chunk_cache import digest

    blend = make_scene("bumps", tmp_path / "b.blend")
    args = [blend, "--object", "Bumps", "--preset", "draft", "--directions", "hemi:32",
            "--resolution", "8", "--device", "cpu", "--direct", "cycles"]
    results = {}
    for label in ("same device", "other device", "mixed"):
        out = tmp_path / label.replace(" ", "_")
        r = relight("bake-chunk", *args, "--chunk", "0", "--out", out)
        assert r.returncode == 0, r.stderr[-2000:]
        (root,) = [p for p in (out / ".relight_cache").iterdir() if p.is_dir()]
        (folder,) = [p for p in root.iterdir() if p.is_dir()]
        if label != "same device":
            key = json.loads((folder / "key.json").read_text())
            assert key["device"] == "CPU"
            key["device"] = "GPU:OPTIX"
            (folder / "key.json").write_text(json.dumps(key))
            shutil.move(str(folder), str(root / digest(key)[:20]))
        r = relight("bake-textures", *args, "--no-compare", "--out", out,
                    *(["--mix-devices"] if label == "mixed" else []))
        assert r.returncode == 0, r.stderr[-2000:]
        rep = json.loads((out / "Bumps_texture_report.json").read_text())
        results[label] = (rep, np.load(out / "Bumps_transport_texture.npy"), r.stdout)
    rep, _, stdout = results["same device"]
    assert rep["chunks_reused"] == 1 and "other_device_chunks" not in rep
    rep, _, stdout = results["other device"]
    assert rep["chunks_reused"] == 0 and rep["other_device_chunks"] == {"GPU:OPTIX": 1}
    assert "1 chunks an interrupted bake left were baked on GPU:OPTIX" in stdout, stdout
    same, other = results["same device"][1], results["other device"][1]
    assert np.array_equal(same.view(np.uint16), other.view(np.uint16))
    # --mix-devices: the user agreed to reuse it; counted, said, and (the chunk was in truth
    # baked on this CPU) bit for bit the same
    rep, mixed, stdout = results["mixed"]
    assert rep["chunks_reused"] == 1 and rep["mixed_device_chunks"] == {"GPU:OPTIX": 1}
    assert "other_device_chunks" not in rep
    assert "1 chunks an interrupted bake left on GPU:OPTIX were reused (--mix-devices)" in stdout
    assert np.array_equal(same.view(np.uint16), mixed.view(np.uint16))
    assert not (tmp_path / "other_device" / ".relight_cache").exists()


def test_the_thread_plan_reaches_cycles_and_blas_during_the_bake_and_is_undone(fresh_scene):
    """``--threads 1`` (Device.threads): Cycles' session runs on one fixed thread and BLAS on
    one while Cycles has the cores, both read back at every step of a real bake; afterwards the
    scene's own Performance setting and BLAS's thread counts are as they were; the report's
    device block records the plan."""
    import dataclasses

    import bmesh
    import numpy  # noqa: F401  (its BLAS is loaded: what the plan sets)

    from relightable_textures.lt_addon import blas_threads
    from relightable_textures.operators.base import cycles_device as cd
    from relightable_textures.operators.bakes import transport_bake as tb
    from relightable_textures.operators.base.jobs import run
    from relightable_textures.operators.base.meshes import object_from_bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=8, v_segments=4, radius=1.0)
    obj = object_from_bmesh("Ball", bm, fresh_scene.collection, smooth=True)
    fresh_scene.render.threads_mode = "AUTO"
    blas_before = blas_threads.threads()
    assert blas_before, "NumPy's OpenBLAS is not found: the plan cannot set it here"
    device = dataclasses.replace(cd.resolve("cpu", fresh_scene), threads=1)
    seen = []
    with cd.use(device):
        run(tb.bake_transport(fresh_scene, obj, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
            on_progress=lambda step: seen.append((fresh_scene.render.threads_mode,
                                                  fresh_scene.render.threads,
                                                  set(blas_threads.threads().values()))))
    assert seen and all(s == ("FIXED", 1, {1}) for s in seen), seen
    assert fresh_scene.render.threads_mode == "AUTO"
    assert blas_threads.threads() == blas_before
    plan = device.report()["threads"]
    assert plan["cycles"] == plan["rays"] == plan["blas_fit"] == 1
    assert plan["blas_while_cycles_and_rays"] == 1 and plan["blas_libraries"]


def test_cli_threads_is_checked_and_recorded(tmp_path):
    blend = make_scene("bumps", tmp_path / "b.blend")
    assert_refused(tmp_path, "--threads takes 0 (every core) or a count, got -2",
                   "bake-textures", blend, *TINY, "--threads", "-2", "--out", tmp_path / "o")
    r = relight("bake-textures", blend, *TINY, "--threads", "1", "--no-compare",
                "--out", tmp_path / "o")
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "o" / "Bumps_texture_report.json").read_text())
    assert rep["device"]["threads"]["cycles"] == 1
    assert rep["direct"]["engine"] == "rays" and rep["direct"]["threads"] == 1
