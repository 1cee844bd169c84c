"""Development tooling of Relightable Textures: benchmarks, Pareto fronts and charts.

Not part of the extension: the zip leaves this folder out (``blender_manifest.toml``
``paths_exclude_pattern``, checked by ``tests/blender/test_extension_install.py``), and it may
use packages Blender does not ship (matplotlib, in requirements.txt). From a source checkout
the ``relight`` command gains the ``bench`` verb (:mod:`.bench_cli`) and ``relight analyze``
draws its charts (:mod:`.charts`). Presets measured here are written into the checkout's
``operators/bakes/presets.json``, never into an installed package.
"""
