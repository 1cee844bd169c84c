"""Bake presets (Draft / Balanced / Production) of both texture methods, chosen from measured
data: one system, one file format.

Each method's presets live in a JSON file next to this module (``presets.json`` for the lobes
bake, ``transport_presets.json`` for transport textures), in one schema::

    {"source": {"command": ..., "scene": ..., "machine": ..., "date" or "rule": ...},
     "presets": {"draft": {"settings": {field: value, ...},
                           "figures": {"bake_seconds": ..., "rel_rmse": ..., ...},
                           "why": "the rule that chose it"}, ...}}

``settings`` are fields of the method's settings dataclass (:class:`Presets` ignores others);
``figures`` what was measured for exactly those settings; a field the file leaves out keeps
the preset's built-in value (``fallback``). The measuring tools (``relight bench
--write-presets``, ``benchmarks/bench_transport_textures.py --write-presets``) write their file
into their output folder, never into the package; adopting new presets is copying that file
here in a commit. ``fallback`` alone serves when the file is missing or unreadable, and the
panel then says the presets are not measured.
"""

from __future__ import annotations

import dataclasses
import json
import os

from ...lt_addon.errors import InputError
from ...lt_addon.transport.bundle import TransportTextureSettings
from .steerable_bake import TextureBakeSettings

PRESET_NAMES = ("draft", "balanced", "production")
HERE = os.path.dirname(os.path.abspath(__file__))


class Presets:
    """The presets of one settings dataclass ``cls``, read from ``filename`` next to this
    module. ``drops``: an override of the key drops the preset's values of the fields listed
    (a --tol of one's own replaces the preset's fixed component count)."""

    def __init__(self, cls, filename: str, fallback: dict, drops: dict | None = None,
                 scales: dict | None = None):
        self.cls, self.path, self.drops = cls, os.path.join(HERE, filename), drops or {}
        self.scales = scales or {}
        self._fallback = fallback
        fields = {f.name for f in dataclasses.fields(cls)}
        data = self._read()
        self.measured = bool(data)
        self._rows = {}
        for name in PRESET_NAMES:
            row = data["presets"][name] if data else {"settings": {}}
            # the file's values over the built-in ones: a file that leaves a field out (the
            # transport presets' tol) keeps the preset's own value, not the dataclass default
            merged = {**fallback[name], **row["settings"]}
            self._rows[name] = {
                "settings": {k: v for k, v in merged.items() if k in fields},
                "figures": ({**row.get("figures", {}), "why": row.get("why", ""),
                             "scene": row.get("figures", {}).get(
                                 "scene", data["source"].get("scene", "?")),
                             "machine": data["source"].get("machine", "?")}
                            if data else {})}

    def _read(self) -> dict:
        try:
            with open(self.path) as fh:
                data = json.load(fh)
        except (OSError, ValueError):
            return {}
        ok = (isinstance(data.get("presets"), dict) and set(PRESET_NAMES) <= set(data["presets"])
              and all("settings" in data["presets"][n] for n in PRESET_NAMES))
        return data if ok else {}

    @property
    def names(self) -> tuple:
        return PRESET_NAMES

    def values(self, name: str) -> dict:
        """The fields preset ``name`` sets (unknown names raise InputError)."""
        if name not in self._rows:
            raise InputError(f"unknown preset {name!r}; choose one of {', '.join(PRESET_NAMES)}")
        return dict(self._rows[name]["settings"])

    def settings(self, name: str, **overrides):
        """A settings object of preset ``name`` with ``overrides`` applied. A ``resolution``
        above the preset's own scales the fields in ``scales`` with it (those not overridden
        and not 0), up to each one's cap: :func:`scaled`."""
        values = self.values(name)
        for key in overrides:
            for dropped in self.drops.get(key, ()):
                values.pop(dropped, None)
        if "resolution" in overrides and "resolution" in values:
            values.update({k: v for k, v in scaled(values, overrides["resolution"],
                                                   self.scales).items()
                           if k not in overrides})
        return self.cls(**{**values, **overrides})

    def figures(self, name: str) -> dict:
        """What was measured for preset ``name`` (``bake_seconds``, ``rel_rmse`` ..., ``why``,
        ``scene``, ``machine``); {} when not measured."""
        return dict(self._rows[name]["figures"])


def scaled(values: dict, resolution: int, caps: dict) -> dict:
    """The fields ``caps`` names, of a preset's ``values`` measured at its own
    ``values["resolution"]``, for a texture of side ``resolution``: multiplied by how many times
    larger it is (never smaller than the preset's), at most the cap, or the preset's value when
    that is larger; 0 (the texture's side) stays 0."""
    ratio = max(1.0, int(resolution) / max(int(values["resolution"]), 1))
    return {k: (v if not v else max(v, min(cap, int(round(v * ratio)))))
            for k, cap in caps.items() if (v := values.get(k)) is not None}


#: The lobes bake's presets (relight bench --scene bumps --write-presets). The built-in values
#: are the file's (it wins when present; these serve only without it): kept equal by
#: tests/core/test_presets_fallback.py.
LOBES = Presets(TextureBakeSettings, "presets.json", {
    "draft": dict(order=3, resolution=128, samples=16, bounces=2, storage="u8"),
    "balanced": dict(order=3, resolution=128, samples=64, bounces=2, storage="u8"),
    "production": dict(order=5, resolution=256, samples=64, bounces=2, storage="u8")})

#: The transport bake's presets (benchmarks/bench_transport_textures.py --write-presets), the
#: file's values built in as for LOBES, and each preset's own PCA tolerance, which the file leaves
#: out (what a --components of one's own falls back to: tests/blender/test_settings.py).
TRANSPORT = Presets(TransportTextureSettings, "transport_presets.json", {
    "draft": dict(directions="hemi:400:1.5", resolution=128, indirect_resolution=64,
                  indirect_samples=64, components=48, table_size=32, horizon_azimuths=64,
                  tol=0.03),
    "balanced": dict(directions="hemi:400:1.5", resolution=256, indirect_resolution=128,
                     indirect_samples=64, components=96, table_size=32, horizon_resolution=0,
                     horizon_azimuths=96, tol=0.02),
    "production": dict(directions="hemi:2800:1.5", resolution=256, indirect_resolution=256,
                       indirect_samples=256, components=256, table_size=64, tol=0.01)},
    drops={"tol": ("components",)},
    # the indirect grid is chosen at the presets' 256^2; a larger texture scales it with it,
    # up to 512^2 (the statue demo at 1024^2, balanced, bench_viewports 2026-12-04: what auto
    # shows erred 0.062 against a 10-degree Sun with the 128^2 grid, 0.052 with a 512^2 one; the
    # bake took 1.8x and 3.5x one 64-spp bake). The horizon side is not scaled: at 512^2 instead
    # of 128^2 the ground's error stayed 0.058 (0.057) and the bake took 94 s more
    scales={"indirect_resolution": 512})

#: Each texture method's presets, by the panel's and the CLI's method name.
BY_METHOD = {"lobes": LOBES, "transport": TRANSPORT}
#: The lobes bake's presets as settings objects (what the panel's lobes fields start from).
PRESETS = {name: LOBES.settings(name) for name in PRESET_NAMES}


def settings_from_preset(name: str, **overrides) -> TextureBakeSettings:
    """A lobes bake's settings: preset ``name`` with ``overrides`` (the transport bake's are
    :func:`.texture_transport.settings_from_preset`)."""
    return LOBES.settings(name, **overrides)


def preset_figures() -> dict:
    """The lobes presets' measured figures by name; {} when not measured."""
    return {n: LOBES.figures(n) for n in PRESET_NAMES} if LOBES.measured else {}
