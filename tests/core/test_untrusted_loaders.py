"""Each loader of a bake file, fed crafted files (issue 56: one validated loader per format).

A bake folder may come from someone else; every loader must refuse a truncated, byte-flipped,
oversized or inconsistent file with one :class:`UntrustedFileError` (an InputError) whose
message starts with the file's path -- never a raw IndexError / BadZipFile / KeyError, never a
relight of garbage, and never an allocation sized by a number the file states (checked with
tracemalloc: the peak stays at kilobytes where the file claims terabytes)."""

import json
import os
import struct
import tracemalloc
import zipfile

import numpy as np
import pytest

from relightable_textures.lt_addon.errors import InputError
from relightable_textures.lt_addon.io import exrio, untrusted as ut
from relightable_textures.lt_addon.io.untrusted import UntrustedFileError
from relightable_textures.lt_addon.sphere.directions import hemisphere_fibonacci
from relightable_textures.lt_addon.transport import bundle, texture as tt

R, S = 8, 40


def _T(seed=3):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0 / np.pi, size=(S, R, R)).astype(np.float32)


def _bundle(tmp_path, model="pca"):
    """A committed transport bundle written by the real writer (no bpy)."""
    dset = hemisphere_fibonacci(S, 1.5)
    T = _T()
    store = tt.TransportStore.create(str(tmp_path / "Patch_transport.npy"), dset, R)
    for s in range(S):
        store.write(s, T[s])
    store = store.finish()
    albedo = np.full((R, R, 3), 0.5, np.float32)
    settings = bundle.TransportTextureSettings(directions=f"hemi:{S}:1.5", resolution=R,
                                               bounces=0, model=model, sun_angle=2.0)
    fitted = bundle.fit_model(store, settings, albedo)
    ob = bundle.ObjectBake("Patch", store.path, albedo, None, fitted, 0.0, store)
    result = bundle.TransportTextureResult([ob], dset, settings, {"bake_total": 1.0}, S)
    (report,) = bundle.write_bundle(result, ["Patch"], str(tmp_path), version="test")
    return report


def _refused(path, fn, *args, match=""):
    """``fn(*args)`` raises UntrustedFileError whose message starts with ``path``."""
    with pytest.raises(UntrustedFileError) as info:
        fn(*args)
    msg = str(info.value)
    assert msg.startswith(str(path)), msg
    assert "\n" not in msg
    if match:
        assert match in msg, msg
    return msg


def _relight(report_path):
    bake, store, rep = bundle.load_bake(report_path)
    return bundle.relight(bake, store, np.array([0.3, 0.2, 0.93]) / np.linalg.norm(
        [0.3, 0.2, 0.93]), source="transport")


def _data_offset(path):
    return ut.npy_header(path)[3]


# ------------------------------------------------------------------------------------------
# 1. T: its header, its values, the report's checksum

def test_a_good_bundle_loads_and_relights_within_t_s_range(tmp_path):
    rep = _bundle(tmp_path)
    assert set(rep["checksums"]) >= {"transport", "transport_header", "albedo", "model"}
    assert all(v.startswith("sha256:") for v in rep["checksums"].values())
    img = _relight(rep["report"])
    assert np.isfinite(img).all() and 0.0 <= img.min() and img.max() <= 1.0 / np.pi


def _overwrite(path, offset, raw: bytes):
    with open(path, "r+b") as fh:
        fh.seek(offset)
        fh.write(raw)


@pytest.mark.parametrize("fill", ["garbage", "nan"])
def test_t_with_finite_garbage_or_nan_is_refused_naming_t(tmp_path, fill):
    """Finite garbage (values up to 60000, far over 1/pi) relit to a mean of 3.06 before; NaN
    went into exports. Here the report's checksum is dropped (as in a report written before
    checksums): the range check alone refuses it."""
    rep = _bundle(tmp_path)
    T = rep["files"]["transport"]
    vals = (np.full(S * R * R, np.nan, np.float16) if fill == "nan" else
            np.random.default_rng(0).uniform(0, 60000, S * R * R).astype(np.float16))
    _overwrite(T, _data_offset(T), vals.tobytes())
    data = json.load(open(rep["report"]))
    del data["checksums"]
    json.dump(data, open(rep["report"], "w"))
    msg = _refused(T, _relight, rep["report"])
    assert ("NaN" in msg) if fill == "nan" else ("above" in msg)


def test_a_t_changed_after_the_bake_does_not_match_its_report_s_checksum(tmp_path):
    rep = _bundle(tmp_path)
    T = rep["files"]["transport"]
    _overwrite(T, _data_offset(T) + 10, np.float16(0.1).tobytes())   # in range: only the
    _refused(T, bundle.load_bake, rep["report"],                      # checksum tells
             match="does not match the checksum its report records (changed after the bake?)")
    # a report of a bake before checksums (no field) still loads, range-checked only
    data = json.load(open(rep["report"]))
    del data["checksums"]
    json.dump(data, open(rep["report"], "w"))
    assert np.isfinite(_relight(rep["report"])).all()


def test_the_model_file_changed_after_the_bake_is_refused(tmp_path):
    rep = _bundle(tmp_path)
    m = rep["files"]["model"]
    with open(m, "ab") as fh:
        fh.write(b"\0")
    _refused(m, bundle.load_bake, rep["report"], match="does not match the checksum")


def _store_files(tmp_path, T=None, dtype=np.float16):
    dset = hemisphere_fibonacci(S, 1.5)
    st = tt.TransportStore.create(str(tmp_path / "t.npy"), dset, R)
    for s in range(S):
        st.write(s, (_T() if T is None else T)[s])
    st.finish().commit()
    return str(tmp_path / "t.npy"), str(tmp_path / "t.json")


def _edit_header(hpath, **changes):
    h = json.load(open(hpath))
    h.update(changes)
    json.dump(h, open(hpath, "w"))


def test_a_t_header_with_a_huge_resolution_or_direction_count_allocates_nothing(tmp_path):
    """resolution 10^6 sized np.zeros((S, 10^12)) (8 TB) before; now refused from the header,
    with kilobytes allocated."""
    path, hpath = _store_files(tmp_path)
    _edit_header(hpath, resolution=10 ** 6)
    tracemalloc.start()
    try:
        msg = _refused(hpath, tt.TransportStore.open, path, match="resolution")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 << 20, peak
    _edit_header(hpath, resolution=R, directions={"spec": "hemi:10000000"})
    _refused(hpath, tt.TransportStore.open, path, match="direction")
    _edit_header(hpath, directions={"directions": [[0, 0, 1]] * 70000,
                                    "solid_angles": [1e-4] * 70000})
    _refused(hpath, tt.TransportStore.open, path, match="direction")
    _edit_header(hpath, resolution="8")
    _refused(hpath, tt.TransportStore.open, path, match="resolution is str")
    h = json.load(open(hpath))
    del h["resolution"]
    json.dump(h, open(hpath, "w"))
    _refused(hpath, tt.TransportStore.open, path, match="has no resolution")
    del msg


@pytest.mark.parametrize("case", ["one great circle", "all under the horizon", "one point"])
def test_a_t_header_whose_directions_cannot_be_interpolated_is_refused_when_read(tmp_path,
                                                                                 case):
    """Directions that do not surround the zenith (S of them on the horizon's circle, all
    under it, all the same) made Qhull fail at the first relight, in a traceback line naming
    no file; now the header is refused when the store is opened, naming it. The set the bake
    writes opens."""
    path, hpath = _store_files(tmp_path)
    tt.TransportStore.open(path)
    t = np.linspace(0, 2 * np.pi, S, endpoint=False)
    d = {"one great circle": np.stack([np.cos(t), np.sin(t), 0 * t], -1),
         "all under the horizon": np.stack([np.cos(t), np.sin(t), -0.5 + 0 * t], -1),
         "one point": np.tile([[0.3, 0.0, 0.95]], (S, 1))}[case]
    _edit_header(hpath, directions={"directions": d.tolist(), "solid_angles": [0.05] * S})
    _refused(hpath, tt.TransportStore.open, path, match="cannot be interpolated")


def test_a_t_whose_npy_disagrees_with_its_header_is_refused_before_mapping(tmp_path):
    path, hpath = _store_files(tmp_path)
    good = open(path, "rb").read()
    # truncated
    open(path, "wb").write(good[:len(good) // 2])
    _refused(path, tt.TransportStore.open, path, match="truncated")
    # another shape (a header edited to a smaller resolution than the data)
    open(path, "wb").write(good)
    _edit_header(hpath, resolution=4)
    _refused(path, tt.TransportStore.open, path, match="has shape")
    _edit_header(hpath, resolution=R)
    # another dtype / byte order
    for dt in (">f2", "<f8", "<i2"):
        np.save(path, _T().reshape(S, -1).astype(dt))
        _refused(path, tt.TransportStore.open, path, match="float16 or float32")
    # not an NPY at all
    open(path, "wb").write(b"\x93NUMPY garbage" + bytes(100))
    _refused(path, tt.TransportStore.open, path, match="NPY")
    # the header is not JSON / is a FIFO / a symlink
    np.save(path, _T().reshape(S, -1).astype(np.float16))
    open(hpath, "w").write('{"format": ')
    _refused(hpath, tt.TransportStore.open, path, match="not valid JSON")


def test_t_s_values_are_checked_as_a_relight_reads_its_rows(tmp_path):
    """A relight reads a few rows; those rows are range-checked (not the whole of a large T),
    and a dense read checks all of it."""
    T = _T()
    path, _ = _store_files(tmp_path, T)
    arr = np.load(path, mmap_mode="r+")
    arr[7, 3] = 2.0                                      # one bad value in row 7
    arr.flush()
    del arr
    st = tt.TransportStore.open(path)
    assert np.isfinite(st.relight([0, 1], [0.5, 0.5])).all()     # rows 0, 1: fine
    _refused(path, st.relight, [7], [1.0], match="above")
    _refused(path, lambda: tt.TransportStore.open(path).relight_dense(np.ones(S)),
             match="above")


def test_the_range_check_is_cheap_on_a_256_squared_t():
    """The cost the brief asked for: 400 directions x 65536 texels of float16 (50 MiB) --
    measured ~4 ms warm (two integer reductions per block); generous bound for a shared CI."""
    import time

    a = (np.random.default_rng(0).random((400, 65536), dtype=np.float32) / np.pi).astype(
        np.float16)
    ut.check_values("T", a, lo=tt.T_LO, hi=tt.T_HI)
    t0 = time.perf_counter()
    ut.check_values("T", a, lo=tt.T_LO, hi=tt.T_HI)
    assert time.perf_counter() - t0 < 0.5


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64])
def test_check_values_finds_every_nan_inf_and_out_of_range_value(dtype):
    rng = np.random.default_rng(1)
    a = (rng.random(5000) / np.pi).astype(dtype)
    ut.check_values("f", a, lo=0.0, hi=1 / np.pi + 1e-3)
    for bad, match in ((np.nan, "NaN"), (-np.nan, "NaN"), (np.inf, "NaN"), (-np.inf, "NaN"),
                       (0.5, "above"), (-0.25, "below")):
        b = a.copy()
        b[rng.integers(len(b))] = bad
        with pytest.raises(UntrustedFileError, match=match):
            ut.check_values("f", b, lo=0.0, hi=1 / np.pi + 1e-3, block=777)


# ------------------------------------------------------------------------------------------
# 2. sizes read from files: EXR headers, NPZ members, direction specs, table sizes

def test_an_npz_member_claiming_more_than_it_holds_is_refused_before_inflating(tmp_path):
    """A forged zip header: a member that says it inflates to 4 GB from a few bytes (a
    deflate bomb's signature) is refused by its stated sizes; nothing is inflated."""
    rep = _bundle(tmp_path)
    m = rep["files"]["model"]
    np.savez_compressed(m, kind=np.array("pca"), V=np.zeros((S, 2), np.float32),
                        U=np.zeros((2, R * R), np.float16), resolution=np.array(R),
                        residual=np.array(0.0))
    raw = bytearray(open(m, "rb").read())
    at = raw.find(b"PK\x01\x02")                  # the first central directory entry
    raw[at + 24:at + 28] = struct.pack("<I", 0xFFFFFFF0)     # its uncompressed size
    open(m, "wb").write(bytes(raw))
    tracemalloc.start()
    try:
        _refused(m, ut.open_npz, m, match="inflates")      # the stated sizes, any NPZ
        _refused(m, tt.load_model, m, match="is compressed")   # a model: stored members only
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 << 20, peak


def test_a_model_npz_that_is_not_a_zip_or_has_wrong_shapes_is_refused(tmp_path):
    rep = _bundle(tmp_path)
    m = rep["files"]["model"]
    good = open(m, "rb").read()
    open(m, "wb").write(good[:len(good) // 2])
    _refused(m, tt.load_model, m, match="NPZ")
    st = tt.TransportStore.open(rep["files"]["transport"])
    np.savez(m, kind=np.array("pca"), V=np.zeros((S + 1, 2), np.float32),
             U=np.zeros((2, R * R), np.float16), resolution=np.array(R), residual=np.array(0.0))
    _refused(m, tt.load_model, m, st, match="has shape")
    np.savez(m, kind=np.array("pca"), V=np.zeros((S, 2), np.float32),
             U=np.zeros((2, R * R), np.float16), resolution=np.array(10 ** 6),
             residual=np.array(0.0))
    _refused(m, tt.load_model, m, match="resolution")
    np.savez(m, kind=np.array("pca"), V=np.full((S, 2), np.nan, np.float32),
             U=np.zeros((2, R * R), np.float16), resolution=np.array(R), residual=np.array(0.0))
    _refused(m, tt.load_model, m, match="NaN")


def test_an_exr_whose_header_claims_a_huge_image_is_refused_before_its_pixels(tmp_path):
    path = str(tmp_path / "wide.exr")
    exrio.write_exr(path, {"R": np.zeros((1, ut.MAX_RESOLUTION + 1), np.float32)})
    tracemalloc.start()
    try:
        _refused(path, exrio.read_exr, path, match="pixels")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 << 20, peak
    exrio.write_exr(path, {"R": np.zeros((64, 64), np.float32)})
    _refused(path, exrio.read_exr, path, 1000, match="inflate")       # over a given cap
    open(path, "wb").write(b"v/1\x01" + bytes(64))
    _refused(path, exrio.read_exr, path, match="OpenEXR")


def test_a_steerable_texture_whose_metadata_claims_a_huge_size_allocates_nothing(tmp_path):
    """order^2 x resolution^2 x 3 floats was allocated from the metadata before the channels
    were looked at."""
    from relightable_textures.lt_addon.steerable.texture import SteerableTexture

    path = str(tmp_path / "lobes.exr")
    meta = {"format": "relightable_textures.steerable_texture", "format_version": 1,
            "order": 12, "resolution": 16384, "storage": "half"}
    exrio.write_exr(path, {"b00.R": np.zeros((4, 4), np.float32)}, meta)
    tracemalloc.start()
    try:
        _refused(path, SteerableTexture.load, path, match="channels")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 << 20, peak
    exrio.write_exr(path, {"b00.R": np.zeros((4, 4), np.float32)}, {**meta, "order": 10 ** 6})
    _refused(path, SteerableTexture.load, path, match="order")


@pytest.mark.parametrize("spec", ["hemi:100000", "halton:70000", "latlong:300x300", "cube:200"])
def test_direction_specs_are_capped_with_one_input_error_line(spec):
    with pytest.raises(InputError, match="the limit is 65536") as info:
        tt.parse_directions(spec)
    assert "\n" not in str(info.value)


def test_a_report_s_table_size_and_sun_angle_are_checked(tmp_path):
    """The preview loops over table_size^2 disk texels: a report's 10^6 was a 10^12 loop."""
    rep = _bundle(tmp_path)
    path = rep["report"]
    good = json.load(open(path))
    for key, value, match in (("table_size", 10 ** 6, "table_size"),
                              ("table_size", "32", "table_size is str"),
                              ("sun_angle", float("nan"), "sun_angle"),
                              ("kernel", "box", "kernel")):
        data = json.loads(json.dumps(good))
        data["settings"][key] = value
        open(path, "w").write(json.dumps(data))
        _refused(path, bundle.load_bake, path, match=match)


# ------------------------------------------------------------------------------------------
# 3. sparse matrices from files

def _tensors_with_receiver_transfer():
    from scipy import sparse

    from relightable_textures.lt_addon.transport import ptt
    from relightable_textures.lt_addon.transport.gathered_transfer import ReceiverTransfer

    import test_ptt

    t = test_ptt.make()
    V, R1 = t.direct.shape[1], len(t.regions) + 1
    rng = np.random.default_rng(0)
    m = sparse.random(R1 * V, V, density=0.05, format="csc", random_state=1, dtype=np.float32)
    S1 = t.one.shape[0]
    t.receiver_transfer = ReceiverTransfer(m, rng.random((S1, V)).astype(np.float16),
                                           np.ones((V, 3), np.float32))
    return ptt, t


def _rewrite(path, **changes):
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(changes)
    np.savez(path, **arrays)


def test_transfer_tensors_with_sparse_indices_out_of_range_are_refused(tmp_path):
    """The receiver transfer's CSC arrays went to SciPy unchecked and were multiplied in C++
    (an out-of-bounds write) by the material-edit handler."""
    ptt, t = _tensors_with_receiver_transfer()
    path = str(tmp_path / "m.npz")
    t.save(path)
    back = ptt.TransferTensors.load(path)                        # the good file loads
    assert (back.receiver_transfer.matrix != t.receiver_transfer.matrix).nnz == 0
    with np.load(path) as z:
        idx, ptr = z["fix_indices"].copy(), z["fix_indptr"].copy()
    bad = idx.copy()
    bad[len(bad) // 2] = 10 ** 6
    _rewrite(path, fix_indices=bad)
    _refused(path, ptt.TransferTensors.load, path, match="indices outside")
    neg = idx.copy()
    neg[0] = -1
    _rewrite(path, fix_indices=neg)
    _refused(path, ptt.TransferTensors.load, path, match="indices outside")
    swapped = ptr.copy()
    swapped[1], swapped[2] = ptr[2] + 5, ptr[1]
    _rewrite(path, fix_indices=idx, fix_indptr=swapped)
    _refused(path, ptt.TransferTensors.load, path, match="indptr")
    _rewrite(path, fix_indptr=ptr[:-1])
    _refused(path, ptt.TransferTensors.load, path, match="indptr")
    long_ptr = ptr.copy()
    long_ptr[-1] += 10
    _rewrite(path, fix_indptr=long_ptr)
    _refused(path, ptt.TransferTensors.load, path, match="indptr")


def test_transfer_tensors_with_bad_regions_or_header_are_refused(tmp_path):
    ptt, t = _tensors_with_receiver_transfer()
    path = str(tmp_path / "m.npz")
    t.save(path)
    with np.load(path) as z:
        reg = z["receiver_region"].copy()
    reg[0] = 99
    _rewrite(path, receiver_region=reg)
    _refused(path, ptt.TransferTensors.load, path, match="regions")
    _rewrite(path, receiver_region=reg * 0, header=np.frombuffer(b"{not json", np.uint8))
    _refused(path, ptt.TransferTensors.load, path, match="not JSON")


def test_check_sparse_costs_less_than_scipy_s_full_check():
    """The brief asked to measure: NumPy's O(nnz) checks before construction vs building and
    ``check_format(full_check=True)``. Both linear; ours runs before any SciPy code."""
    import time

    from scipy import sparse

    n, per = 20000, 100                                       # 2 M values
    rng = np.random.default_rng(0)
    indptr = np.arange(n + 1, dtype=np.int32) * per
    indices = np.sort(rng.integers(0, n, (n, per), dtype=np.int32), axis=1).ravel()
    data = rng.random(n * per, dtype=np.float32)
    t0 = time.perf_counter()
    ut.check_sparse("m", indices, indptr, n, n, len(data))
    ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    sparse.csc_matrix((data, indices, indptr), shape=(n, n)).check_format(full_check=True)
    theirs = time.perf_counter() - t0
    print(f"check_sparse {ours * 1e3:.1f} ms, scipy full check {theirs * 1e3:.1f} ms")
    assert ours < 0.5 and theirs < 5.0, (ours, theirs)


# ------------------------------------------------------------------------------------------
# 4. reports: not JSON, truncated, missing keys, links and FIFOs

def test_a_report_that_is_not_json_truncated_or_missing_keys_names_itself(tmp_path):
    rep = _bundle(tmp_path)
    path = rep["report"]
    good = open(path).read()
    open(path, "w").write(good[:len(good) // 2])
    _refused(path, bundle.load_bake, path, match="not valid JSON")
    open(path, "w").write("\x00\x01binary")
    _refused(path, bundle.load_bake, path)
    open(path, "w").write("[1, 2]")
    _refused(path, bundle.load_bake, path, match="JSON list")
    for key in ("files", "settings", "object"):
        data = json.loads(good)
        del data[key]
        open(path, "w").write(json.dumps(data))
        _refused(path, bundle.load_bake, path, match=f"has no {key}")
    data = json.loads(good)
    del data["files"]["albedo"]
    open(path, "w").write(json.dumps(data))
    _refused(path, bundle.load_bake, path, match="has no files.albedo")
    data = json.loads(good)
    data["files"]["transport"] = "../../etc/passwd"       # a basename under the folder only
    open(path, "w").write(json.dumps(data))
    _refused(os.path.join(os.path.dirname(path), "passwd"), bundle.load_bake, path,
             match="missing")


def test_a_report_that_is_a_symlink_or_a_fifo_is_refused(tmp_path):
    rep = _bundle(tmp_path)
    path = rep["report"]
    link = str(tmp_path / "link_report.json")
    os.symlink(path, link)
    _refused(link, bundle.load_bake, link, match="symbolic link")
    fifo = str(tmp_path / "fifo_report.json")
    os.mkfifo(fifo)
    _refused(fifo, bundle.load_bake, fifo, match="FIFO")        # and it did not block
    # a file of the bundle replaced by a symlink (to the same bytes) is refused too
    T = rep["files"]["transport"]
    os.rename(T, T + ".real")
    os.symlink(T + ".real", T)
    _refused(T, bundle.load_bake, path, match="symbolic link")


def test_other_bundle_files_give_one_line_naming_them(tmp_path):
    rep = _bundle(tmp_path)
    data = json.load(open(rep["report"]))
    del data["checksums"]
    json.dump(data, open(rep["report"], "w"))
    albedo = rep["files"]["albedo"]
    open(albedo, "wb").write(b"not an exr")
    _refused(albedo, bundle.load_bake, rep["report"], match="OpenEXR")
    exrio.write_exr(albedo, {c: np.zeros((R + 1, R), np.float32) for c in "RGB"})
    _refused(albedo, bundle.load_bake, rep["report"], match="shape")


def test_a_deflated_member_in_a_format_written_uncompressed_is_refused_unread(tmp_path):
    """A transport model is always written stored (np.savez / save_npz); the same arrays
    deflated -- the shape of a ~1000:1 bomb whose header matches what the reader expects -- are
    refused before any member is inflated (issue 56: the ratio cap alone let 1030:1 through)."""
    import zipfile

    from relightable_textures.lt_addon.io import untrusted as ut
    from relightable_textures.lt_addon.io.npz import save_npz

    good = tmp_path / "m.npz"
    save_npz(good, a=np.zeros((256, 256), np.float32))
    with ut.open_npz(str(good), stored=True) as z:
        assert z.get("a").shape == (256, 256)
    bomb = tmp_path / "bomb.npz"
    save_npz(bomb, compressed=True, a=np.zeros((256, 256), np.float32))
    assert zipfile.ZipFile(bomb).infolist()[0].compress_size < 1000   # 256 KiB from < 1 KiB
    with pytest.raises(ut.UntrustedFileError, match="is compressed; this tool writes"):
        ut.open_npz(str(bomb), stored=True)


def test_an_npy_header_cut_inside_its_dict_is_refused_in_one_line(tmp_path):
    """Found by the fuzz harness: numpy's header parser tokenizes the header's text, and a dict
    left open ends in tokenize.TokenError, which no loader caught (a traceback at the CLI)."""
    head = b"{'descr': '<f4', 'shape': (3,\n"
    p = tmp_path / "t.npy"
    p.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head + b"\0" * 12)
    _refused(p, ut.load_npy, str(p), match="is not a whole NPY file")


def test_exr_metadata_of_another_attribute_type_is_refused(tmp_path):
    """Found by the fuzz harness: a flipped bit in the metadata attribute's type name made
    OpenEXR hand back an opaque attribute, and json.loads raised TypeError."""
    import OpenEXR

    p = str(tmp_path / "m.exr")
    exrio.write_exr(p, {"R": np.zeros((4, 4), np.float32)}, metadata={"a": 1})
    raw = bytearray(open(p, "rb").read())
    at = raw.find(exrio.METADATA_KEY.encode()) + len(exrio.METADATA_KEY) + 1
    assert raw[at:at + 6] == b"string"
    raw[at:at + 6] = b"strinf"                      # an attribute type OpenEXR does not know
    open(p, "wb").write(bytes(raw))
    with OpenEXR.File(p, header_only=True) as f:   # (the library reads it, as another type)
        assert not isinstance(f.header()[exrio.METADATA_KEY], (str, bytes))
    _refused(p, exrio.read_exr, p, match="is not text")


def test_an_npz_asking_for_a_newer_zip_version_is_refused_in_one_line(tmp_path):
    """Found by the hour-long fuzz run: a damaged 'version needed to extract' field makes
    zipfile.ZipFile raise NotImplementedError ("zip file version 16.2") while opening."""
    from relightable_textures.lt_addon.io.npz import save_npz

    p = tmp_path / "v.npz"
    save_npz(p, a=np.zeros(4, np.float32))
    raw = bytearray(p.read_bytes())
    at = raw.find(b"PK\x01\x02")                          # the central directory entry
    raw[at + 6:at + 8] = struct.pack("<H", 162)           # version needed: 16.2
    p.write_bytes(bytes(raw))
    _refused(p, ut.open_npz, str(p), match="is not a whole NPZ file")
