"""Development tooling of Relightable Textures: benchmarks, Pareto fronts and charts.

Not part of the extension: the zip leaves this folder out (``blender_manifest.toml``
``paths_exclude_pattern``, checked by ``tests/blender/test_extension_install.py``), and it may
use packages Blender does not ship (matplotlib, in requirements.txt). Where this package is
installed (a source checkout's venv) the ``relight`` command gains the ``bench`` verb
(:mod:`.bench_cli`) and ``relight analyze`` draws its charts (:mod:`.charts`), through the entry
points of ``pyproject.toml`` (:mod:`..lt_addon.plugins`): the product never imports this
package. Presets measured here are written into the output folder, never into the package.
"""
