"""The chunk cache of resumable bakes: keys, atomic chunks, stale folders (no Blender)."""

import os

import numpy as np

from relightable_textures.lt_addon.io.chunk_cache import ChunkCache, digest


def test_digest_is_canonical_and_changes_with_any_value():
    assert digest({"a": 1, "b": [1.5, "x"]}) == digest({"b": [1.5, "x"], "a": 1})
    assert digest({"a": 1}) != digest({"a": 2}) != digest({"a": 1, "c": None})


def test_chunks_round_trip_bit_for_bit_and_a_new_key_sees_none(tmp_path):
    rng = np.random.default_rng(0)
    half = rng.normal(size=(2, 16, 64)).astype(np.float16)
    c = ChunkCache(str(tmp_path / "out" / "cache"), {"scene": "s1", "res": 8})
    assert c.get("direct_00000") is None
    c.put("direct_00000", half)
    back = ChunkCache(str(tmp_path / "out" / "cache"), {"res": 8, "scene": "s1"}).get("direct_00000")
    assert back.dtype == np.float16 and np.array_equal(back.view(np.uint16), half.view(np.uint16))
    assert not [n for n in os.listdir(c.folder) if n.startswith(".")]   # no temporaries left
    other = ChunkCache(str(tmp_path / "out" / "cache"), {"scene": "s2", "res": 8})
    assert other.get("direct_00000") is None
    other.put("direct_00000", half)
    assert other.prune_others() == 1 and sorted(os.listdir(tmp_path / "out" / "cache")) == [
        os.path.basename(other.folder)]
    other.clear()
    assert not os.path.exists(tmp_path / "out")        # the empty root and its parent go


def test_a_truncated_chunk_counts_as_missing_and_is_removed(tmp_path):
    c = ChunkCache(str(tmp_path), {"k": 1})
    c.put("x", np.arange(1000, dtype=np.float16))
    with open(c.path("x"), "r+b") as fh:                # a crash of the file system, say
        fh.truncate(100)
    assert c.get("x") is None and not os.path.exists(c.path("x"))
    assert c.reused == 0 and c.written == 1


def test_a_nested_stage_cache_survives_the_outer_prune_and_both_clear(tmp_path):
    """A bake's stages with different keys: the indirect stage's cache nested in the direct
    stage's root is not taken for a stale key folder; cleared inner first, nothing is left."""
    root = tmp_path / "out" / ".relight_cache" / "A"
    direct = ChunkCache(str(root), {"stage": "direct"})
    lights = ChunkCache(str(root / "indirect"), {"stage": "lights"})
    lights.put("light_00000", np.zeros(3, np.float32))
    direct.put("direct_00000", np.zeros(3, np.float16))
    stale = ChunkCache(str(root), {"stage": "direct", "old": True})
    stale.put("direct_00000", np.zeros(3, np.float16))
    assert direct.prune_others() == 1
    assert sorted(os.listdir(root)) == sorted([os.path.basename(direct.folder), "indirect"])
    assert lights.get("light_00000") is not None
    lights.clear()
    direct.clear()
    assert os.listdir(tmp_path / "out") == []


def test_a_chunk_with_other_bytes_or_non_finite_values_is_baked_again(tmp_path):
    """Issue 34's faulty chunk: a valid .npy whose values are NaN (what a faulty worker or disk
    can leave) was reused and the bake died at the end. Now a chunk is reused only when its
    checksum (written by put) matches and its floats are finite; otherwise it is removed with
    its checksum and counted as rejected, so the bake makes it again."""
    c = ChunkCache(str(tmp_path), {"k": 1})
    good = np.linspace(0, 1, 64, dtype=np.float16).reshape(8, 8)
    for name in ("same", "nan", "edited", "unsigned"):
        c.put(name, good)
    np.save(c.path("nan"), np.full_like(good, np.nan))          # replaced behind put's back
    bad = good.copy()
    bad[3, 3] += np.float16(0.25)
    np.save(c.path("edited"), bad)                               # finite, but not what put wrote
    os.remove(c.path("unsigned") + ".sha256")                    # killed between the two writes
    np.testing.assert_array_equal(c.get("same"), good)
    for name in ("nan", "edited", "unsigned"):
        assert c.get(name) is None, name
        assert not os.path.exists(c.path(name)) and not os.path.exists(c.path(name) + ".sha256")
    assert (c.reused, c.rejected, c.written) == (1, 3, 4)
    # a NaN the bake itself put is refused too (a faulty Cycles result is not kept)
    c.put("nan_put", np.full(4, np.nan, np.float32))
    assert c.get("nan_put") is None and c.rejected == 4


def test_a_chunk_of_the_wrong_shape_dtype_or_range_is_baked_again(tmp_path):
    """A kept chunk whose checksum holds but which is not what this bake needs (another
    layout, a dtype a bug wrote, values no irradiance can have) is refused and counted."""
    cache = ChunkCache(str(tmp_path / "c"), {"k": 1})
    good = np.full((1, 4, 16), 0.25, np.float16)
    for name, arr in {"shape": good.reshape(1, 16, 4), "dtype": good.astype(np.float32),
                      "range": good + np.float16(1.0), "ok": good}.items():
        cache.put(name, arr)
    want = dict(shape=(1, 4, 16), dtype=np.float16, lo=0.0, hi=1.0)
    assert [cache.get(n, **want) is None for n in ("shape", "dtype", "range")] == [True] * 3
    assert cache.rejected == 3 and not os.path.exists(cache.path("shape"))
    np.testing.assert_array_equal(cache.get("ok", **want), good)
    assert cache.reused == 1


def test_an_adopted_chunk_of_another_device_is_reused_only_while_mixing(tmp_path):
    """--mix-devices moves another device's chunks into this key's folder with a note of where
    they came from: reused and counted while mixing; a later run without it bakes them again
    and says whose they were."""
    root = str(tmp_path / "c")
    gpu = ChunkCache(root, {"k": 1, "device": "GPU:OPTIX"})
    gpu.put("direct_00000", np.ones((1, 2, 4), np.float16))
    mixed = ChunkCache(root, {"k": 1, "device": "CPU"})
    mixed.prune_others(adopt_devices=True)
    assert mixed.get("direct_00000") is not None and mixed.mixed_devices == {"GPU:OPTIX": 1}
    later = ChunkCache(root, {"k": 1, "device": "CPU"})
    later.prune_others()
    assert later.get("direct_00000") is None and later.other_devices == {"GPU:OPTIX": 1}
    later.put("direct_00000", np.zeros((1, 2, 4), np.float16))   # baked here now: its own
    assert later.get("direct_00000") is not None and later.other_devices == {"GPU:OPTIX": 1}
