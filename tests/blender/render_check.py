"""Render the open scene to a float EXR and read it back (shared by the preview tests)."""

import numpy as np

from relightable_textures.lt_addon.io import exrio


def render_rgb(scene, tmp_path, resolution: int, engine: str = "CYCLES") -> np.ndarray:
    """One-sample render at ``resolution``^2 with pixel centres on texel centres; (R, R, 3)
    float64, row 0 at the bottom. The world is removed so only the preview emits. The preview
    targets EEVEE only (issue 57: renders keep the user's material), so a Cycles render here
    lets Cycles see it for this render (``preview_nodes.render_previews``)."""
    import bpy

    from relightable_textures.operators.preview import preview_nodes

    scene.update_tag()
    bpy.context.view_layer.update()
    scene.render.engine = engine
    scene.render.resolution_x = scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    if engine == "CYCLES":
        scene.cycles.samples = 1
        scene.cycles.use_denoising = False    # (on in the factory scene: it smears 1 spp)
        scene.cycles.filter_width = 0.01  # sample pixel centres = texel centres
    else:
        scene.eevee.taa_render_samples = 1
        scene.render.filter_size = 0.0
    scene.world = None
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = str(tmp_path / f"render-{engine.lower()}.exr")
    undo = preview_nodes.render_previews(list(scene.objects), engine)
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        for f in undo:
            f()
    ch, _ = exrio.read_exr(scene.render.filepath)
    return np.stack([ch["R"], ch["G"], ch["B"]], -1).astype(np.float64)
