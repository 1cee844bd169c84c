"""Relightable Textures: a Blender extension.

This module must stay importable without bpy (pytest imports ``relightable_textures.lt_addon``
through it), so all bpy work happens inside :func:`register` / :func:`unregister`.
"""

__version__ = "0.1.0"


def register():
    from .operators import registration

    registration.register()


def unregister():
    from .operators import registration

    registration.unregister()
