"""Extension points that packages outside the product fill, by Python entry points (group
:data:`GROUP`): the development tools of a source checkout add the ``relight bench`` verb and
the ``relight analyze`` charts this way (``pyproject.toml``), so the product never imports
them or guesses from an ImportError whether they are there.

An entry point's name says what it is: ``verb:<name>`` is a function ``add_parser(sub)`` that
adds a verb to the ``relight`` sub-parsers; ``analysis-charts`` a function
``(report, out_dir, name) -> {kind: path}`` that draws ``relight analyze``'s charts (it returns
{} when it cannot draw, e.g. without matplotlib). The Blender extension has no installed
distribution under its import name, so inside Blender there are none."""

from __future__ import annotations

GROUP = "relightable_textures.plugins"


#: This package's import name: ``relightable_textures`` in a venv, ``bl_ext.<repo>.
#: relightable_textures`` inside Blender.
PACKAGE = __name__.rsplit(".lt_addon.", 1)[0]


def _entry_points():
    """The group's entry points that belong to this very package: a plugin of the venv's
    ``relightable_textures`` is not one of the Blender extension's (same code, another import
    name: in a venv that also has the extension installed, it would load a second copy)."""
    from importlib.metadata import entry_points

    try:
        found = list(entry_points(group=GROUP))
    except Exception:   # a broken distribution elsewhere in the environment: no plugins
        return []
    return [ep for ep in found if ep.value.split(":")[0].startswith(PACKAGE + ".")]


def verbs() -> list:
    """The ``add_parser`` functions of the installed ``verb:`` plugins, by name."""
    return [ep.load() for ep in sorted(_entry_points(), key=lambda e: e.name)
            if ep.name.startswith("verb:")]


def get(name: str):
    """The plugin called ``name`` (loaded), or None when none is installed."""
    for ep in _entry_points():
        if ep.name == name:
            return ep.load()
    return None
