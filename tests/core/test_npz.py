"""lt_addon.io.npz: NPZ files np.load reads back, and a failed write is one exception with no
``Exception ignored in ZipFile.__del__`` traceback after it (np.savez printed one on a full
disk; here a real RLIMIT_FSIZE in a subprocess)."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from relightable_textures.lt_addon.io.npz import save_npz


@pytest.mark.parametrize("compressed", [False, True])
def test_round_trip_as_np_load_reads_it(tmp_path, compressed):
    arrays = {"a": np.arange(7, dtype=np.int64), "b": np.eye(3, dtype=np.float16),
              "s": np.array("hemi:64"), "e": np.zeros((0, 4), np.float32)}
    save_npz(tmp_path / "m.npz", compressed=compressed, **arrays)
    with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
        assert sorted(z.files) == sorted(arrays)
        for k, v in arrays.items():
            assert z[k].dtype == v.dtype and np.array_equal(z[k], v)


def test_object_arrays_are_refused(tmp_path):
    with pytest.raises(ValueError):
        save_npz(tmp_path / "o.npz", o=np.array([{}, None], dtype=object))


def test_a_full_disk_is_one_exception(tmp_path):
    """(np.savez printed the second traceback with numpy 1.26.4, 2026-12-06.)"""
    code = textwrap.dedent(f"""
        import gc, resource, signal
        import numpy as np
        from relightable_textures.lt_addon.io.npz import save_npz
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (100000, 100000))
        try:
            save_npz({str(tmp_path / 'big.npz')!r}, a=np.ones(100000))
        except OSError as exc:
            print("one error", exc.errno)
        gc.collect()
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "one error 27" in r.stdout, r.stderr
    assert r.stderr == "", r.stderr
