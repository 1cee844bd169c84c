"""Extension points that packages outside the product fill, by Python entry points (group
:data:`GROUP`): the development tools of a source checkout add the ``relight bench`` verb and
the ``relight analyze`` charts this way (``pyproject.toml``), so the product never imports
them or guesses from an ImportError whether they are there.

An entry point's name says what it is: ``verb:<name>`` is a function ``add_parser(sub)`` that
adds a verb to the ``relight`` sub-parsers; ``analysis-charts`` a function
``(report, out_dir, name) -> {kind: path}`` that draws ``relight analyze``'s charts (it returns
{} when it cannot draw, e.g. without matplotlib). The Blender extension has no installed
distribution, so inside Blender there are none."""

from __future__ import annotations

GROUP = "relightable_textures.plugins"


def _entry_points():
    from importlib.metadata import entry_points

    try:
        return list(entry_points(group=GROUP))
    except Exception:   # a broken distribution elsewhere in the environment: no plugins
        return []


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
