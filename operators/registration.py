"""Register / unregister everything the extension adds to Blender (bpy).

Also registers the ``relight`` command-line command, so inside Blender
``blender -b [FILE.blend] --command relight VERB ...`` runs the same verbs as the venv CLI.
"""

from __future__ import annotations

import bpy

from .ui import bake_ops, export_ops, material_ops, panel, properties, scene_ops, study_ops
from . import cli
from .preview import render_guard

CLASSES = (properties.CLASSES + scene_ops.CLASSES + bake_ops.CLASSES + material_ops.CLASSES
           + export_ops.CLASSES + study_ops.CLASSES + panel.CLASSES)
CLI_COMMAND = "relight"
_cli_handles = []


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    properties.register()
    material_ops.register()
    render_guard.register()
    _cli_handles.append(bpy.utils.register_cli_command(CLI_COMMAND, cli.run))


def unregister() -> None:
    while _cli_handles:
        bpy.utils.unregister_cli_command(_cli_handles.pop())
    render_guard.unregister()
    material_ops.unregister()
    properties.unregister()
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
