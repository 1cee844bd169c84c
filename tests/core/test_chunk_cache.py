"""The chunk cache of resumable bakes: keys, atomic chunks, stale folders (no Blender)."""

import os
import stat

import numpy as np
import pytest

from relightable_textures.lt_addon.io import chunk_cache
from relightable_textures.lt_addon.io.chunk_cache import ChunkCache, digest
from relightable_textures.lt_addon.io.untrusted import UntrustedFileError


@pytest.fixture(autouse=True)
def _own_key(tmp_path_factory, monkeypatch):
    """Each test's chunk key in a folder of its own (never the user's ~/.cache)."""
    monkeypatch.setenv("RELIGHT_CHUNK_KEY_FILE",
                       str(tmp_path_factory.mktemp("key") / "chunk-key"))


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


# ------------------------------------------------------------------------------------------
# issue 56: the chunk cache is untrusted input -- never followed through a link, and a chunk
# is reused only when it carries this user's keyed checksum


def _tree(folder):
    """Every entry under ``folder`` (links not followed) with its bytes (None: a folder)."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for d in dirs:
            out[os.path.relpath(os.path.join(root, d), folder)] = None
        for f in files:
            p = os.path.join(root, f)
            out[os.path.relpath(p, folder)] = open(p, "rb").read()
    return out


def _elsewhere(tmp_path):
    """A folder outside the bake folder holding a key-like folder with a chunk, and an empty
    folder: what a link in the cache would lead to."""
    ext = tmp_path / "elsewhere"
    (ext / "empty").mkdir(parents=True)
    (ext / "0123456789abcdef0123").mkdir()
    np.save(ext / "0123456789abcdef0123" / "direct_00000.npy", np.ones(4, np.float16))
    (ext / "keep.txt").write_bytes(b"keep")
    return ext, _tree(ext)


def test_a_symlinked_cache_root_is_refused_in_one_line_and_nothing_outside_changes(tmp_path):
    """``bk/.relight_cache`` a link to a folder elsewhere: the bake wrote through it and its
    prune removed the 20-hex folder and the empty one there. Now making the cache refuses:
    the message names the link and says to remove it."""
    ext, before = _elsewhere(tmp_path)
    (tmp_path / "bk").mkdir()
    os.symlink(ext, tmp_path / "bk" / ".relight_cache")
    with pytest.raises(UntrustedFileError) as err:
        cache = ChunkCache(str(tmp_path / "bk" / ".relight_cache" / "A"), {"k": 1})
        cache.prune_others()
        cache.put("direct_00000", np.zeros(4, np.float16))
        cache.clear()
    msg = str(err.value)
    assert msg.startswith(str(tmp_path / "bk" / ".relight_cache") + ": ")
    assert "symbolic link" in msg and "remove it" in msg and "\n" not in msg
    assert _tree(ext) == before


def test_a_symlinked_key_folder_or_stale_folder_is_never_followed(tmp_path):
    ext, before = _elsewhere(tmp_path)
    root = tmp_path / "bk" / ".relight_cache" / "A"
    root.mkdir(parents=True)
    mine = ChunkCache(str(root), {"k": 1})
    os.symlink(ext, mine.folder)                        # this key's folder is a link
    with pytest.raises(UntrustedFileError, match="symbolic link"):
        ChunkCache(str(root), {"k": 1}).put("direct_00000", np.zeros(4, np.float16))
    os.remove(mine.folder)
    os.symlink(ext / "0123456789abcdef0123", root / "fedcba9876543210fedc")   # a stale key's
    other = ChunkCache(str(root), {"k": 2, "device": "CPU"})
    with pytest.raises(UntrustedFileError, match="symbolic link"):
        other.prune_others(adopt_devices=True)
    assert _tree(ext) == before
    other.clear()                                       # (removes only what is its own)
    assert _tree(ext) == before and os.path.islink(root / "fedcba9876543210fedc")


def test_a_symlinked_chunk_is_not_read_and_its_target_stays(tmp_path):
    ext, before = _elsewhere(tmp_path)
    cache = ChunkCache(str(tmp_path / "c"), {"k": 1})
    cache.put("direct_00000", np.zeros(4, np.float16))
    target = ext / "0123456789abcdef0123" / "direct_00000.npy"
    os.remove(cache.path("direct_00000"))
    os.symlink(target, cache.path("direct_00000"))      # a link with a valid keyed checksum
    with open(cache.path("direct_00000") + ".sha256", "w") as fh:
        fh.write(chunk_cache.MAC_PREFIX + chunk_cache.mac(str(target), chunk_cache.chunk_key(),
                                                          "direct_00000.npy") + "\n")
    assert cache.get("direct_00000") is None and cache.rejected == 1
    assert not os.path.lexists(cache.path("direct_00000"))   # the link went, not its target
    assert _tree(ext) == before
    cache.clear()
    assert _tree(ext) == before


def test_a_planted_chunk_with_a_valid_unkeyed_checksum_is_baked_again(tmp_path):
    """The cache key can be computed from the .blend and SHA-256 needs no secret: anyone who
    can write the folder could plant a chunk the bake reused as its output. Now the checksum is
    an HMAC under this user's key: the planted chunk is refused and baked again."""
    cache = ChunkCache(str(tmp_path / "c"), {"k": 1})
    os.makedirs(cache.folder)
    planted = np.full((2, 4), 0.5, np.float16)
    np.save(cache.path("direct_00000"), planted)
    with open(cache.path("direct_00000") + ".sha256", "w") as fh:
        fh.write(chunk_cache.checksum(planted) + "\n")        # SHA-256 of shape, dtype, bytes
    assert cache.get("direct_00000", (2, 4), np.float16) is None
    assert cache.rejected == 1 and not os.path.exists(cache.path("direct_00000"))
    cache.put("direct_00000", planted)                   # baked here: this user's key
    assert cache.get("direct_00000", (2, 4), np.float16) is not None


def test_the_key_is_made_once_private_and_another_users_key_rejects_the_chunks(
        tmp_path, monkeypatch):
    key_file = tmp_path / "keys" / "chunk-key"
    monkeypatch.setenv("RELIGHT_CHUNK_KEY_FILE", str(key_file))
    cache = ChunkCache(str(tmp_path / "c"), {"k": 1})
    cache.put("x", np.arange(4, dtype=np.float32))
    if os.name == "posix":
        assert stat.S_IMODE(os.stat(key_file).st_mode) == 0o600
    secret = key_file.read_bytes()
    assert len(secret) >= 32
    assert ChunkCache(str(tmp_path / "c"), {"k": 1}).get("x") is not None
    assert key_file.read_bytes() == secret              # read, not made again
    monkeypatch.setenv("RELIGHT_CHUNK_KEY_FILE", str(tmp_path / "other-user-key"))
    again = ChunkCache(str(tmp_path / "c"), {"k": 1})
    assert again.get("x") is None and again.rejected == 1


def test_the_default_key_lives_in_the_users_cache_folder(tmp_path, monkeypatch):
    monkeypatch.delenv("RELIGHT_CHUNK_KEY_FILE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setenv("LOCALAPPDATA", str(tmp_path / "xdg"))
    path = chunk_cache.key_file()
    assert path.startswith(str(tmp_path / "xdg" / "relightable-textures"))
    chunk_cache.chunk_key()
    assert os.path.isfile(path)


def test_a_chunk_is_checked_against_its_header_before_its_data_is_read(tmp_path):
    """A chunk whose header claims more data than the file has, or another shape than the
    bake asks for, is refused from its header (nothing of that size is allocated)."""
    cache = ChunkCache(str(tmp_path / "c"), {"k": 1})
    cache.put("big", np.zeros((2, 4), np.float16))
    hdr = b"{'descr': '<f2', 'fortran_order': False, 'shape': (1099511627776,), }"
    # a header that says 2**40 values, then 16 bytes
    raw = b"\x93NUMPY\x01\x00" + len(hdr.ljust(118) + b"\n").to_bytes(2, "little") \
        + hdr.ljust(118) + b"\n" + b"\x00" * 16
    with open(cache.path("big"), "wb") as fh:
        fh.write(raw)
    assert cache.get("big") is None and cache.rejected == 1
    cache.put("small", np.zeros((2, 4), np.float16))
    assert cache.get("small", shape=(4, 2)) is None and cache.rejected == 2


def test_a_chunk_of_records_round_trips(tmp_path):
    """Chunks of a structured dtype (the gathered transfer's entries: origin, column, weight)
    are numbers too: kept, checked and reused like any other."""
    entry = np.dtype([("origin", np.int64), ("column", np.int64), ("weight", np.float64)])
    rec = np.zeros(5, entry)
    rec["weight"] = np.linspace(0, 1, 5)
    cache = ChunkCache(str(tmp_path / "c"), {"k": 1})
    cache.put("gather_00000", rec)
    back = ChunkCache(str(tmp_path / "c"), {"k": 1}).get("gather_00000")
    assert back is not None and back.dtype == entry and np.array_equal(back, rec)
