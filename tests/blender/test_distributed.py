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
from relight_cli import BIN, assert_refused, relight

TINY = ["--object", "Bumps", "--directions", "hemi:400", "--resolution", "16", "--bounces",
        "0", "--model", "none", "--no-compare"]


@pytest.fixture(scope="module")
def blend(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dist")
    path = folder / "b.blend"
    assert relight("scene", "bumps", "--out", path).returncode == 0
    r = relight("bake-textures", path, *TINY, "--no-resume", "--out", folder / "ref")
    assert r.returncode == 0, r.stderr[-2000:]
    return path, np.load(folder / "ref" / "Bumps_transport_texture.npy")


def _same_bits(a, b):
    return a.shape == b.shape and np.array_equal(a.view(np.uint16), b.view(np.uint16))


def test_two_local_workers_bake_the_same_bits_as_one_process(blend, tmp_path):
    path, ref = blend
    r = relight("bake-textures", path, *TINY, "--workers", "2", "--out", tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    import json

    rep = json.loads((tmp_path / "Bumps_texture_report.json").read_text())
    dist = rep["distributed"]
    assert dist["chunks"] == rep["chunks_total"] == 25 and rep["chunks_reused"] == 0
    assert len(dist["workers"]) == 2 and dist["file_loads"] == 2   # each worker opened it once
    assert dist["cycles_threads_per_worker"] == max(1, os.cpu_count() // 2)
    assert "distributed: 25 chunks on 2 worker processes" in r.stdout
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
    assert_refused(tmp_path, "cannot reach the Dask scheduler at tcp://127.0.0.1:9",
                   "bake-textures", path, *TINY, "--scheduler", "tcp://127.0.0.1:9",
                   "--out", tmp_path / "o")
    assert_refused(tmp_path, "drop --no-resume", "bake-textures", path, *TINY, "--workers", "2",
                   "--no-resume", "--out", tmp_path / "o")
    assert_refused(tmp_path, "apply to --method transport", "bake-textures", path,
                   "--object", "Bumps", "--method", "lobes", "--workers", "2")
    assert not (tmp_path / "o").exists()


def test_a_worker_refuses_a_scene_that_is_not_the_one_being_baked(blend, tmp_path):
    """The worker compares its file's cache key with the coordinator's: an unsaved change (here
    a key for another scene) is one clear error, never a chunk of the wrong scene."""
    from dataclasses import asdict

    from relightable_textures.operators import distributed
    from relightable_textures.operators.texture_transport import TransportTextureSettings

    path, _ = blend
    s = asdict(TransportTextureSettings(directions="hemi:400", resolution=16, bounces=0,
                                        model="none"))
    with pytest.raises(distributed.DistributedError, match="not the scene being baked"):
        distributed.bake_chunk(str(path), ["Bumps"], s, 0, 16, str(tmp_path),
                               {"scene": {"objects": {}}})
    assert not list(tmp_path.iterdir())
