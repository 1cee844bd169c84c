"""Settings declared once (lt_addon/settings.py): what the panel's Run On sends is what the CLI
parses back, the panel's properties carry the declared ranges, and the declared ranges are
the ones a bake enforces.

Independent of the declarations' own code paths: the argv goes through the real ``relight``
parser (argparse), the properties are read back from Blender's RNA after registration."""

import dataclasses

import pytest

pytestmark = pytest.mark.blender


def _cases():
    from relightable_textures.lt_addon.export.fitting import ExportSettings
    from relightable_textures.lt_addon.transport.bundle import TransportTextureSettings
    from relightable_textures.operators.bakes.material_bake import MaterialBakeSettings
    from relightable_textures.operators.bakes.steerable_bake import TextureBakeSettings
    from relightable_textures.operators.bakes.transport_bake import TransportSettings

    head = ["f.blend", "--object", "X"]
    return [  # (verb and its required arguments, settings with every declared value changed)
        (["bake-textures"] + head,
         TransportTextureSettings(directions="hemi:64:2", resolution=96, bounces=3,
                                  indirect_resolution=48, indirect_samples=7, model="blocks",
                                  components=5, tol=0.05, sun_angle=4.5, table_size=48,
                                  seed=9, viewport="pca")),
        (["bake-textures", "--method", "lobes"] + head,
         TextureBakeSettings(order=5, resolution=64, samples=9, bounces=1, frame="tangent",
                             mode="irradiance", storage="u8", seed=3, world_sampling="none")),
        (["bake-materials", "--region", "M"] + head,
         MaterialBakeSettings(regions=["M"], anchors="roughness:0.4,0.8", anchor_samples=17,
                              bounces=1, samples=5, seed=2, smoothing=0.5, bounce_bake="cycles",
                              rays=64, anchor_directions="hemi:32")),
        (["bake-transport", "f.blend", "--object", "X"],
         TransportSettings(directions="halton:64", bounces=2, samples=8, energy=0.95)),
        (["export", "f.blend", "--object", "X"],
         ExportSettings(format="rti-ptm", terms=6, rotate=30.0, sun_angle=3.0, strength=2.5,
                        exposure=1.5, held_out=8)),
    ]


def test_run_on_argv_parses_back_to_the_same_settings():
    """to_argv(settings) through the real parser gives every declared value back (a declared
    field the CLI lacks, or a flag spelt differently, fails here)."""
    from relightable_textures.lt_addon.settings import declared, to_argv
    from relightable_textures.operators.cli import build_parser

    parser = build_parser()
    for verb, settings in _cases():
        args = parser.parse_args(verb + to_argv(settings))
        for s in declared(type(settings)):
            want = getattr(settings, s.name)
            assert getattr(args, s.name) == want, (verb[0], s.name)


def test_declared_ranges_are_the_enforced_ones():
    """One past each declared bound, every bake's validate() refuses, naming the field."""
    from relightable_textures.lt_addon.errors import InputError
    from relightable_textures.lt_addon.settings import declared

    checked = 0
    for _, settings in _cases():
        for s in declared(type(settings)):
            for bad in ([s.hi + (1 if s.kind == "int" else 0.5)] if s.hi is not None else []) + \
                       ([s.lo - (1 if s.kind == "int" else 0.5)] if s.lo is not None else []):
                broken = dataclasses.replace(settings, **{s.name: bad})
                with pytest.raises(InputError):
                    broken.validate()
                checked += 1
    assert checked >= 30       # the declarations above carry at least this many bounds


def test_the_panel_properties_carry_the_declared_ranges_and_help(fresh_scene):
    import bpy

    import relightable_textures
    from relightable_textures.lt_addon.settings import declared
    from relightable_textures.lt_addon.transport.bundle import TransportTextureSettings
    from relightable_textures.operators.bakes.material_bake import MaterialBakeSettings
    from relightable_textures.operators.ui import properties as pr

    relightable_textures.register()
    try:
        rna = bpy.types.Scene.bl_rna.properties["relight"].fixed_type.properties
        rows = [(TransportTextureSettings, pr.TRANSPORT_FIELDS, pr.TRANSPORT_PROPS),
                (MaterialBakeSettings, pr.MATERIAL_FIELDS, pr.MATERIAL_PROPS)]
        for cls, fields, rename in rows:
            for s in declared(cls, fields):
                prop = rna[rename.get(s.name, s.name)]
                assert prop.description == s.help
                if s.lo is not None:
                    assert prop.hard_min == pytest.approx(s.lo), s.name
                if s.hi is not None:
                    assert prop.hard_max == pytest.approx(s.hi), s.name
                if s.choices:
                    assert [i.identifier for i in prop.enum_items] == [c[0] for c in s.choices]
    finally:
        relightable_textures.unregister()


def test_a_preset_keeps_the_values_its_file_leaves_out():
    """transport_presets.json states no tol: each preset keeps its own (draft 0.03, balanced
    0.02, production 0.01, the built-in table), not the dataclass default 0.02 -- the reading
    the one preset system first got wrong (found in review, 2026-12-02)."""
    import json
    import pathlib

    from relightable_textures.operators.bakes.presets import TRANSPORT

    path = pathlib.Path(TRANSPORT.path)
    assert all("tol" not in p["settings"]
               for p in json.loads(path.read_text())["presets"].values())
    assert [TRANSPORT.settings(n).tol for n in ("draft", "balanced", "production")] == [
        0.03, 0.02, 0.01]
    # a --tol of one's own drops the preset's fixed component count (PCA by tolerance)
    assert TRANSPORT.settings("balanced").components == 96
    assert TRANSPORT.settings("balanced", tol=0.05).components is None


def test_a_larger_texture_scales_the_presets_indirect_grid_with_it_up_to_512():
    """The presets' indirect grid was chosen at 256^2 (draft at 128^2): a larger texture
    multiplies it by how many times larger it is, up to 512; a smaller one keeps it; the
    horizon side and an explicit value stay."""
    from relightable_textures.operators.bakes.presets import TRANSPORT

    def sides(name, **kw):
        t = TRANSPORT.settings(name, **kw)
        return t.indirect_resolution, t.horizon_resolution

    # (horizons 0: the texture's side, at most 1024 -- every preset's since balanced's 96^2
    # lost to T on a relief: docs/bench/2026-12-gallery.md)
    assert sides("balanced") == sides("balanced", resolution=128) == (128, 0)
    assert sides("balanced", resolution=512) == (256, 0)
    assert sides("balanced", resolution=1024) == sides("balanced", resolution=4096) == (512, 0)
    assert sides("draft", resolution=256) == (128, 0) and sides("draft", resolution=2048)[0] == 512
    assert sides("production", resolution=1024) == (512, 0)
    assert sides("balanced", resolution=2048, indirect_resolution=64,
                 horizon_resolution=96) == (64, 96)


def test_a_southern_study_parses_as_typed():
    """``--study -33.87,...`` (a southern latitude first) is the study, not an unknown option
    (argparse alone refuses it: "expected one argument"); other values are left as they are."""
    from relightable_textures.operators.cli import build_parser
    from relightable_textures.operators.cli.commands import _join_signed_values

    study = "-33.87,151.21,Australia/Sydney,2026-06-21"
    argv = ["bake-textures", "x.blend", "--object", "A", "--study", study, "--sun-path-step", "1"]
    assert build_parser().parse_args(_join_signed_values(argv)).study == study
    assert _join_signed_values(["--study", "--force"]) == ["--study", "--force"]
    assert _join_signed_values(["--lat", "-3", "--study"]) == ["--lat", "-3", "--study"]
