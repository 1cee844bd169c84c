"""A transport bake's cost predicted before it starts (issue 33): two calibration bakes at 64^2
and 128^2 fit each stage's fixed and per-texel cost on this machine; the prediction for a larger
bake is held against that bake's measured time in the same process."""

import os

from relight_cli import make_scene, our_lines, relight


def test_the_estimate_is_within_30_percent_of_the_bake_it_predicts(tmp_path):
    """The test-size bumps at 256^2 (4x the texels of the largest calibration), draft preset,
    estimated and then baked in one run (--estimate is implied at 512^2 and up; asked here):
    the report holds the estimate and the measured bake time, within 30 %.

    The calibration bakes take about a second, and a busy neighbour on a shared machine during
    them moves the extrapolation: measured 2026-12-03 on bpy 5.3.0 with 48^2 and 96^2, four
    runs in a row gave 0.78, 0.91, 1.05 and 1.13, and CI once saw 1.40; with the horizons the
    bake's largest stage, 64^2 and 128^2 gave 0.94, 0.78, 1.13, 0.94 on bpy 5.0.1 (48^2 and
    96^2: 1.16, 1.26, 1.02, 1.06, and 1.34, 1.25, 1.77 in one make test). So two of at most
    three estimate-and-bake
    runs must land within 30 % (a biased estimator fails every run; most runs pass the first
    two)."""
    import bpy

    from relightable_textures import samples
    from relightable_textures.operators.bakes import texture_transport as tx
    from relightable_textures.operators.bakes.estimate import estimate
    from relightable_textures.operators.base.jobs import run

    ratios = []
    for attempt in range(3):
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        scene = bpy.context.scene
        samples.build("bumps", scene, "test")
        obj = bpy.data.objects["Bumps"]
        settings = tx.settings_from_preset("draft", resolution=256)
        out = run(tx.bake_job(scene, [obj], settings, str(tmp_path / str(attempt)), truth=0,
                              preview=False, compare=False, resume=False, estimator=estimate))
        e = out.reports[0]["estimate"]
        assert set(e["seconds"]) >= {"direct", "indirect", "fit", "other"}
        assert e["calibration_seconds"] > 0 and e["disk_bytes"] > 0
        assert e["measured_bake_seconds"] == out.reports[0]["timings"]["bake_total"]
        ratios.append(e["measured_over_estimated"])
        good = sum(0.7 <= r <= 1.3 for r in ratios)
        if good >= 2 or len(ratios) - good >= 2:
            break
    assert good >= 2, f"measured / estimated bake time in each run: {ratios}"


def test_cli_estimate_prints_the_cost_and_bakes_nothing(tmp_path):
    blend = make_scene("bumps", tmp_path / "b.blend")
    r = relight("bake-textures", blend, "--object", "Bumps", "--preset", "draft",
                "--resolution", "2048", "--estimate", "--out", tmp_path / "o")
    assert r.returncode == 0, r.stderr[-2000:]
    first, second, *notes = r.stdout.strip().splitlines()
    assert first.startswith("estimate for 1 object(s) at 2048^2: about ")
    # the horizons at 1024^2 are a stage of their own; the block fit (T's atlas is over the
    # budget) is timed too, and made only if auto then does not show the horizons
    for what in ("direct", "horizons", "indirect", "fit"):
        assert f"{what} " in first
    # both what auto may skip: the block fit (the horizons shown) or most of the horizons (T
    # clearly closer on the sampled tiles)
    assert len(notes) == 2 and "timed whole" in notes[0] and "block viewport" in notes[1]
    # the disk figure is T's own formula: 479 directions (400 and the 79 of their band under
    # 5 degrees mirrored under the horizon) x 2048^2 texels x 2 bytes
    assert "disk 3.7 GiB for T" in second and "of GPU memory" in second
    assert not (tmp_path / "o").exists() and "relight: error" not in r.stderr


def test_the_panel_estimates_the_bake_and_shows_the_figures(tmp_path):
    """The panel's Estimate (bpy.ops, in process): the lines in the scene for the panel, and
    nothing written to the output folder."""
    import bpy

    import relightable_textures
    from relightable_textures import samples

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    samples.build("bumps", scene, "test")
    obj = bpy.data.objects["Bumps"]
    relightable_textures.register()
    try:
        props = scene.relight
        props.preset = "draft"
        props.resolution, props.device = 1024, "cpu"
        props.output_dir = str(tmp_path / "o") + os.sep
        bpy.context.view_layer.objects.active = obj
        assert bpy.ops.relight.estimate() == {"FINISHED"}
        lines = scene["relight_last_estimate"].splitlines()
        assert lines[0].startswith("estimate for 1 object(s) at 1024^2: about ")
        assert "GPU memory" in lines[1] and not (tmp_path / "o").exists()
    finally:
        relightable_textures.unregister()
