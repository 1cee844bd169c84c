"""Sunlight hours from a transport store (lt_addon/sun/sunlight_hours.py), its pictures
(study_images.py) and the study folder (sun_study.py), on synthetic stores whose T is known in
closed form: ``T = max(0, n . w) V(w) / pi`` with V a wall's shadow. The same against a real
Cycles/ray bake and a brute-force ray count: tests/blender/test_sun_study.py."""

import csv
import json
import os

import numpy as np
import pytest

from relightable_textures.lt_addon.errors import InputError
from relightable_textures.lt_addon.io import exrio
from relightable_textures.lt_addon.io.contact_sheet import read_png
from relightable_textures.lt_addon.sphere.directions import parse_direction_spec
from relightable_textures.lt_addon.sun import study_images as si
from relightable_textures.lt_addon.sun import sun_study as ss
from relightable_textures.lt_addon.sun import sunlight_hours as sh
from relightable_textures.lt_addon.sun.study_times import study_suns, study_times, with_study
from relightable_textures.lt_addon.transport import texture as tt

R = 4


def _normals():
    """16 texels: up, tilted 30 degrees four ways, a south wall, a north wall, east, west,
    ... and texel 15 facing down (never lit)."""
    n = np.zeros((R * R, 3))
    n[:] = (0.0, 0.0, 1.0)
    for i, az in enumerate((0, 90, 180, 270)):
        a = np.radians(az)
        n[1 + i] = (np.sin(a) * np.sin(np.radians(30)), np.cos(a) * np.sin(np.radians(30)),
                    np.cos(np.radians(30)))
    n[5], n[6], n[7], n[8] = (0, -1, 0), (0, 1, 0), (1, 0, 0), (-1, 0, 0)
    n[15] = (0, 0, -1)
    return n


def _vis(D):
    """(S, P) visibility: texels 9..14 sit north of a wall that blocks the south below 30
    degrees (texels 9-11) or the east below 45 degrees (12-14); the others see the sky."""
    D = np.asarray(D, np.float64).reshape(-1, 3)
    az = np.degrees(np.arctan2(D[:, 0], D[:, 1])) % 360.0
    el = np.degrees(np.arcsin(np.clip(D[:, 2], -1, 1)))
    V = np.ones((len(D), R * R))
    south = (az > 135) & (az < 225) & (el < 30)
    east = (az > 45) & (az < 135) & (el < 45)
    V[:, 9:12] = ~south[:, None]
    V[:, 12:15] = ~east[:, None]
    return V


def _T(D, n):
    return np.maximum(np.asarray(D) @ n.T, 0.0) * _vis(D) / np.pi


def _store(tmp_path, dset, name="A"):
    n = _normals()
    store = tt.TransportStore.create(str(tmp_path / f"{name}_transport_texture.npy"), dset, R)
    store.write_rows(0, _T(dset.directions, n))
    store.finish().commit()
    return tt.TransportStore.open(str(tmp_path / f"{name}_transport_texture.npy")), n


def _study(dates=("2026-03-20", "2026-06-21", "2026-12-21"), **kw):
    kw = kw or {"step_minutes": 60}
    times = study_times(list(dates), "Europe/London", **kw)
    suns = study_suns(times, 51.5, -0.13)
    step = times.step_h or 1.0
    wh = np.bincount(suns.index[suns.up], minlength=len(suns.directions)) * step
    return times, suns, wh


def _exact(suns, wh, n):
    D = suns.directions
    return wh @ ((D @ n.T > 0) * _vis(D))


def test_normals_fitted_to_T_are_the_surfaces(tmp_path):
    store, n = _store(tmp_path, parse_direction_spec("hemi:200:1.5"))
    fit = sh.fit_normals(store)
    lit = np.arange(15)
    cos = np.sum(fit[lit] * n[lit], axis=1)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.1     # half floats
    assert np.allclose(np.linalg.norm(fit[lit], axis=1), 1.0, atol=1e-6)
    assert np.all(fit[15] == 0)                                         # never lit: no normal
    # only some texels asked: the same rows
    np.testing.assert_array_equal(sh.fit_normals(store, texels=[3, 9, 15]), fit[[3, 9, 15]])


def test_visibility_is_exact_at_the_baked_directions(tmp_path):
    dset = parse_direction_spec("hemi:200:1.5")
    store, n = _store(tmp_path, dset)
    fit = sh.fit_normals(store)
    D = dset.directions[::7]
    V = sh.visibility(store, fit, D)
    cos = D @ n.T
    expect = _vis(D) * (cos > 0)
    # at a baked direction the ratio is V, except where the sun grazes the surface (its
    # cosine below pi C_MIN = 1e-3: no sun, by definition)
    graze = np.abs(cos) < 2e-3
    assert graze.sum() < 20 and np.all(V[cos < 1e-3] == 0)
    assert np.abs(V - expect)[~graze].max() == 0.0
    np.testing.assert_array_equal(sh.visibility(store, fit, D, texels=[9, 12]), V[:, [9, 12]])


def test_hours_equal_the_exact_count_when_the_bake_holds_the_studys_suns(tmp_path):
    """with_study puts every instant's sun into the direction set: the map is then the count
    of lit hours itself (fraction and threshold alike, a point sun)."""
    times, suns, wh = _study()
    dset = with_study(parse_direction_spec("hemi:100:1.5"), suns, times)
    store, n = _store(tmp_path, dset)
    exact = _exact(suns, wh, n)
    for vis in sh.VISIBILITY:
        got = sh.sunlight_hours(store, suns.directions, wh, visibility=vis)
        assert np.abs(got.hours.ravel()[:15] - exact[:15]).max() == 0.0, vis
        assert got.hours.ravel()[15] == 0 and not got.covered.ravel()[15]
        assert got.possible_h == wh.sum() == 36.0     # London on these 3 dates: 36 hours up
    # texel 0 (up, open sky) gets every hour; the north wall (6) the summer's early and late
    assert got.hours.ravel()[0] == 36.0 and 0 < got.hours.ravel()[6] <= 8


def test_hours_between_the_baked_directions_blend_their_shadows(tmp_path):
    """A 100-direction set alone: the suns fall between its directions, so texels near the
    wall's shadow edge are off (by how much on a real scene: tests/blender/test_sun_study.py);
    an open texel is still exact and every map lies in [0, possible]."""
    times, suns, wh = _study()
    store, n = _store(tmp_path, parse_direction_spec("hemi:100:1.5"))
    exact = _exact(suns, wh, n)
    got = sh.sunlight_hours(store, suns.directions, wh).hours.ravel()
    assert got[0] == exact[0] == 36.0
    assert np.all(got >= 0) and np.all(got <= 36.0)
    assert 0 < np.abs(got[9:15] - exact[9:15]).max() < 10
    assert sh.nearest_baked(store.directions, suns.directions).max() > 3.0
    thr = sh.sunlight_hours(store, suns.directions, wh, visibility="threshold").hours
    assert np.all(np.mod(thr, 1.0) == 0)            # whole hours: each hour lit or not


def test_the_weight_matrix_is_the_relights(tmp_path):
    dset = parse_direction_spec("hemi:100:1.5")
    D = np.array([[0.3, 0.2, 0.93], [0.0, 0.0, -1.0]])
    W = sh.sun_weight_matrix(dset, D, 0.533)
    idx, w = tt.sun_weights(dset, D[0], 0.533)
    np.testing.assert_allclose(W[0].toarray()[0, idx], w)
    assert W[0].sum() == pytest.approx(1.0) and W[1].nnz == 0


def test_the_ramp_the_map_picture_and_the_sheet():
    assert si.ramp(0.0).tolist() == [68, 1, 84] and si.ramp(1.0).tolist() == [253, 231, 37]
    assert si.ramp([-1, 2]).tolist() == [[68, 1, 84], [253, 231, 37]]
    hours = np.array([[0.0, 10.0], [5.0, 0.0]])
    covered = np.array([[True, True], [True, False]])
    img = si.hours_picture(hours, covered, 10.0, ["A: sunlight hours", "place"])
    assert img.dtype == np.uint8 and img.shape[1] == 640
    band = 2 * (9 + 4) * 2                           # two title lines at scale 2
    top_left = img[band + 5, 5]                      # row 1 of the texture (v = 1) at the top
    assert top_left.tolist() == si.ramp(0.5).tolist()
    assert img[band + 5, 635].tolist() == list(si.UNCOVERED)
    assert img[band + 325, 5].tolist() == si.ramp(0.0).tolist()
    assert img[band + 325, 635].tolist() == si.ramp(1.0).tolist()
    cells = [(np.full((4, 4), 0.5), "2026-06-21 09:00", "el 40"), (None, "x", "no such time"),
             (np.zeros((4, 4)), "a", "b")]
    sheet = si.sheet(cells, 2, "title")
    tile = 256 + 2 * 26
    assert sheet.shape == (26 + 2 * tile + 4, 2 * 256 + 4, 3)
    assert sheet[26 + 52 + 10, 10].tolist() == [188] * 3        # 0.5 linear in sRGB


# --- the study folder ---------------------------------------------------------------------

def _bundle(folder, dset, name="A"):
    """A minimal transport-texture bundle as load_bake reads it: T, its header, the albedo and
    the report."""
    store, n = _store(folder, dset, name)
    albedo = np.full((R, R), 0.5, np.float32)
    albedo[-1, -1] = 0.0                                            # texel 15: no texel
    exrio.write_exr(str(folder / f"{name}_albedo.exr"), {c: albedo for c in "RGB"},
                    {"format": "relightable_textures.albedo"})
    report = {"kind": "transport_texture", "format": 1, "object": name,
              "settings": {"sun_angle": 2.0, "kernel": "linear"},
              "files": {"transport": f"{name}_transport_texture.npy",
                        "albedo": f"{name}_albedo.exr"}}
    path = folder / f"{name}_texture_report.json"
    path.write_text(json.dumps(report))
    return str(path), n


def _settings(**kw):
    base = dict(latitude=51.5, longitude=-0.13, tz="Europe/London",
                dates=ss.dates_from(["2026-03-20", "2026-06-21", "2026-12-21"]),
                hours=[9, 12, 15])
    base.update(kw)
    return ss.StudySettings(**base)


def test_a_study_folder_has_the_maps_the_sheet_the_csv_and_the_report(tmp_path):
    bake = tmp_path / "bake"
    bake.mkdir()
    report_path, n = _bundle(bake, parse_direction_spec("hemi:100:1.5"))
    out = tmp_path / "study"
    lines = []
    rep = ss.run_study([report_path], _settings(), str(out), version="x", echo=lines.append)
    assert sorted(os.listdir(out)) == ["A_shadow_study.png", "A_sunlight_hours.exr",
                                       "A_sunlight_hours.png", "sun_study.json",
                                       "sunlight_hours.csv"]
    assert json.loads((out / "sun_study.json").read_text()) == json.loads(json.dumps(rep))
    assert rep["kind"] == "sun_study" and rep["instants"]["count"] == 9
    assert rep["instants"]["possible_h"] == 9.0 and rep["sheet"]["hours"] == [9.0, 12.0, 15.0]
    assert len(rep["instants"]["elevation_deg"]) == 9
    (obj,) = rep["objects"]
    assert obj["object"] == "A" and obj["hours"]["texels"] == 15
    # the EXR holds the hours (float) and the covered texels
    ch, meta = exrio.read_exr(str(out / "A_sunlight_hours.exr"))
    times, suns, wh = _study(hours=[9, 12, 15])
    store = tt.TransportStore.open(str(bake / "A_transport_texture.npy"))
    expect = sh.sunlight_hours(store, suns.directions, wh, sun_angle_deg=ss.SUN_ANGLE_DEG)
    np.testing.assert_array_equal(ch["Y"], expect.hours)
    assert ch["A"].ravel()[15] == 0 and ch["A"].sum() == 15 and meta["unit"] == "hours"
    assert ch["Y"].ravel()[0] == 9.0
    rows = list(csv.DictReader(open(out / "sunlight_hours.csv")))
    assert rows[0]["object"] == "A" and float(rows[0]["max_h"]) == 9.0
    assert float(rows[0]["mean_h"]) == pytest.approx(expect.hours.ravel()[:15].mean(), abs=1e-4)
    # the suns of a 100-direction set are degrees from it: said
    assert obj["nearest_baked_deg"]["far_suns"] == 9 and len(rep["warnings"]) == 1
    # the warning names the bake that adds the study's suns (bake-textures --study)
    assert ("bake with --study 51.5,-0.13,Europe/London,2026-03-20,2026-06-21,2026-12-21 to "
            "add" in rep["warnings"][0]) and lines[0].startswith("A: ")
    sheet = read_png(str(out / "A_shadow_study.png"))
    assert sheet.shape[1] == 3 * 256 + 2 * 4
    # a second run into the same folder is refused without force, done with it
    with pytest.raises(InputError, match="--force"):
        ss.run_study([report_path], _settings(), str(out))
    ss.run_study([report_path], _settings(step_minutes=30, hours=None), str(out), force=True)
    rep2 = json.loads((out / "sun_study.json").read_text())
    assert rep2["instants"]["count"] == 3 * 48 and rep2["sheet"]["what"].startswith("clock")


def test_bad_studies_and_bad_reports_are_refused_before_anything_is_written(tmp_path):
    bake = tmp_path / "bake"
    bake.mkdir()
    report_path, _ = _bundle(bake, parse_direction_spec("hemi:50"))
    out = tmp_path / "study"
    for kw, msg in ((dict(latitude=91), "latitude"), (dict(tz="Mars/Olympus"), "Mars"),
                    (dict(step_minutes=10), "either"), (dict(hours=[25]), "clock hour"),
                    (dict(dates=[]), "date"), (dict(visibility="x"), "visibility"),
                    (dict(hours=None, step_minutes=10, window=(20, 6)), "window")):
        with pytest.raises(InputError, match=msg):
            ss.run_study([report_path], _settings(**kw), str(out))
    with pytest.raises(InputError, match="bad date '2026-13-01'"):
        ss.dates_from(["2026-06-21", "2026-13-01"])
    with pytest.raises(InputError, match="before it starts"):
        ss.dates_from(start="2026-03-01", end="2026-02-01")
    assert len(ss.dates_from(start="2026-01-01", end="2026-12-31", every_days=7)) == 53
    other = bake / "other.json"
    other.write_text(json.dumps({"kind": "steerable_texture"}))
    with pytest.raises(InputError, match="not a transport texture"):
        ss.run_study([report_path, str(other)], _settings(), str(out))
    with pytest.raises(InputError, match="twice"):
        ss.run_study([report_path, report_path], _settings(), str(out))
    assert not out.exists()


def test_daylight_saving_gaps_are_said_and_blank_on_the_sheet(tmp_path):
    bake = tmp_path / "bake"
    bake.mkdir()
    report_path, _ = _bundle(bake, parse_direction_spec("hemi:50"))
    rep = ss.run_study([report_path], _settings(dates=ss.dates_from(["2026-03-29"]),
                                                hours=[1.5, 12]), str(tmp_path / "s"))
    assert rep["instants"]["skipped_clock_times"] == ["2026-03-29T01:30:00"]
    assert any("do not exist" in w for w in rep["warnings"])


def test_a_polar_night_gives_zero_hours_and_says_so(tmp_path):
    bake = tmp_path / "bake"
    bake.mkdir()
    report_path, _ = _bundle(bake, parse_direction_spec("hemi:50"))
    rep = ss.run_study([report_path], _settings(latitude=80.0, longitude=15.0, tz="UTC",
                                                dates=ss.dates_from(["2026-12-21"])),
                       str(tmp_path / "s"))
    assert rep["instants"]["sun_up"] == 0 and rep["objects"][0]["hours"]["max_h"] == 0.0
    assert any("below the horizon" in w for w in rep["warnings"])
    sheet = read_png(str(tmp_path / "s" / "A_shadow_study.png"))
    assert sheet.shape[1] == 3 * 256 + 2 * 4
