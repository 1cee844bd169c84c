"""Bake presets (Draft / Balanced / Production) and their measured figures.

The settings of each preset live here; their *figures* (bake time, error vs Cycles truth,
bytes) are measured by ``make bench`` (``benchmarks/bench_texture_bake.py``) and stored in
``preset_figures.json`` next to this file, which the panel and ``relight bake-textures --help``
show. Nothing here is guessed: a preset without a measurement shows "not measured".
"""

from __future__ import annotations

import json
import os
from dataclasses import replace

from .steerable_bake import TextureBakeSettings

PRESETS = {
    "draft": TextureBakeSettings(order=5, resolution=128, samples=16, bounces=1, storage="u8"),
    "balanced": TextureBakeSettings(order=7, resolution=256, samples=64, bounces=2, storage="half"),
    "production": TextureBakeSettings(order=7, resolution=512, samples=128, bounces=3,
                                      storage="half"),
}
FIGURES_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "preset_figures.json")


def settings_from_preset(name: str, **overrides) -> TextureBakeSettings:
    """A copy of preset ``name`` with ``overrides`` applied (unknown names raise ValueError)."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return replace(PRESETS[name], **overrides)


def preset_figures() -> dict:
    """Measured figures per preset name ({} when the benchmark has not been run)."""
    try:
        with open(FIGURES_PATH) as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return {}
