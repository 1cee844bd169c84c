"""Bake presets (Draft / Balanced / Production), chosen from measured data.

``presets.json`` next to this file holds, per preset, the settings chosen from the Pareto front
of bake time vs error that ``relight bench --scene bumps --write-presets`` measured (draft: the
cheapest front point; production: the most accurate; balanced: the knee, see
:func:`..devtools.pareto.choose_presets`), the figures measured for it and the rule that chose
it. The panel and ``relight bake-textures --preset`` read it. ``FALLBACK`` is used only if the
file is missing or unreadable, and the panel then says the presets are not measured.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace

from .steerable_bake import TextureBakeSettings

PRESET_NAMES = ("draft", "balanced", "production")
PRESETS_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "presets.json")
#: settings keys a preset may set
SETTING_KEYS = ("order", "resolution", "samples", "bounces", "storage")

FALLBACK = {
    "draft": TextureBakeSettings(order=5, resolution=128, samples=16, bounces=1, storage="u8"),
    "balanced": TextureBakeSettings(order=7, resolution=256, samples=64, bounces=2, storage="half"),
    "production": TextureBakeSettings(order=7, resolution=512, samples=128, bounces=3,
                                      storage="half"),
}


def _read() -> dict:
    try:
        with open(PRESETS_PATH) as fh:
            data = json.load(fh)
        return data if set(PRESET_NAMES) <= set(data.get("presets", {})) else {}
    except (OSError, ValueError):
        return {}


def _load_presets() -> dict:
    data = _read()
    if not data:
        return dict(FALLBACK)
    return {name: TextureBakeSettings(**{k: data["presets"][name]["settings"][k]
                                         for k in SETTING_KEYS})
            for name in PRESET_NAMES}


PRESETS = _load_presets()


def settings_from_preset(name: str, **overrides) -> TextureBakeSettings:
    """A copy of preset ``name`` with ``overrides`` applied (unknown names raise ValueError)."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return replace(PRESETS[name], **overrides)


def preset_figures() -> dict:
    """Measured figures per preset name (``bake_seconds``, ``rel_rmse``, ``stored_bytes`` ...,
    plus ``why``, ``scene`` and ``machine``); {} when not measured."""
    data = _read()
    if not data:
        return {}
    source = data.get("source", {})
    return {name: {**p["figures"], "why": p["why"], "scene": source.get("scene", "?"),
                   "machine": source.get("machine", "?")}
            for name, p in data["presets"].items()}
