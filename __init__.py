"""Relightable Textures: a Blender extension.

This module must stay importable without bpy (pytest imports ``relightable_textures.lt_addon``
through it), so all bpy work happens inside :func:`register` / :func:`unregister`.
"""



def _manifest_version() -> str:
    """The version, kept in one place: ``blender_manifest.toml`` (Blender reads it there;
    pyproject.toml takes it from here, and the CLI and bake reports print it)."""
    import os
    import tomllib

    with open(os.path.join(os.path.dirname(os.path.abspath(__file__)),
                           "blender_manifest.toml"), "rb") as fh:
        return tomllib.load(fh)["version"]


__version__ = _manifest_version()


def register():
    from .operators import registration

    registration.register()


def unregister():
    from .operators import registration

    registration.unregister()
