"""One relight path (issue 55): ``relight relight`` shows by default what the panel's viewport
shows for the object -- the report's ``viewport.shows`` (its horizon map, T through sparse
tables, the PCA or blocks) -- so the CLI, the panel and the report's figure are the same
representation. Before, the CLI relit the PCA model whatever the viewport showed (on the real
meshes of issue 55 the ground was 0.132 from the CLI's default and 0.087 from what the panel
showed)."""

import json

from relightable_textures.lt_addon.transport.bundle import VIEWPORT_SOURCES
from relight_cli import make_scene, relight


def test_relight_defaults_to_what_the_viewport_shows(tmp_path):
    import OpenEXR

    blend = make_scene("bumps", tmp_path / "b.blend")
    out = tmp_path / "bk"
    r = relight("bake-textures", blend, "--object", "Bumps", "--preset", "draft",
                "--directions", "hemi:64", "--resolution", "16", "--truth", "0", "--no-compare",
                "--out", out, "--force")
    assert r.returncode == 0, r.stderr[-2000:]
    shows = json.loads((out / "Bumps_texture_report.json").read_text())["viewport"]["shows"]
    expected = VIEWPORT_SOURCES[shows]
    images = {}
    for source in (None, expected, "model" if expected != "model" else "transport"):
        exr = tmp_path / f"{source}.exr"
        r = relight("relight", blend, "--object", "Bumps", "--light", "30,20", "--out", exr,
                    *(["--source", source] if source else []))
        assert r.returncode == 0, r.stderr[-2000:]
        info = json.loads(r.stdout)
        assert info["source"] == (source or expected)
        with OpenEXR.File(str(exr)) as f:
            images[source] = {k: v.pixels.copy() for k, v in f.channels().items()}
    same = lambda a, b: all((images[a][k] == images[b][k]).all() for k in images[a])  # noqa
    assert same(None, expected)          # the default is the viewport's own representation
    assert not same(None, "model" if expected != "model" else "transport")
