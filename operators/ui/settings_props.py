"""The panel's properties made from a bake's declared settings (:mod:`...lt_addon.settings`),
and the settings read back from them, so the panel states no default, range, choice or help
text of its own for them (bpy)."""

from __future__ import annotations

import bpy

from ...lt_addon.settings import declared


def properties(cls, names=None, *, rename=None, defaults=None, update=None) -> dict:
    """``{property name: bpy property}`` for ``cls``'s declared fields ``names`` (default: those
    the panel shows in their own form). ``rename`` maps a field to its property name (a
    ``transport_`` prefix where two bakes share a word); ``defaults`` overrides a default by
    property name (a preset's); ``update`` is every property's update callback. An optional
    integer shows None as 0."""
    rename, defaults = rename or {}, defaults or {}
    out = {}
    for s in declared(cls, names):
        if names is None and not s.panel:
            continue
        prop = rename.get(s.name, s.name)
        default = defaults.get(prop, s.default)
        kw = {"name": s.label, "description": s.help}
        if update is not None:
            kw["update"] = update
        if s.choices:
            out[prop] = bpy.props.EnumProperty(
                items=[(str(v), label, desc) for v, label, desc in s.choices],
                default=str(default), **kw)
            continue
        limits = {k: v for k, v in (("min", s.lo), ("max", s.hi)) if v is not None}
        if s.soft is not None:
            limits.update(soft_min=s.soft[0], soft_max=s.soft[1])
        if s.kind == "int":
            out[prop] = bpy.props.IntProperty(default=int(default or 0), **limits, **kw)
        elif s.kind == "float":
            out[prop] = bpy.props.FloatProperty(default=float(default), **limits, **kw)
        elif s.kind == "bool":
            out[prop] = bpy.props.BoolProperty(default=bool(default), **kw)
        else:
            out[prop] = bpy.props.StringProperty(default=str(default or ""), **kw)
    return out


def values(cls, props, names=None, *, rename=None) -> dict:
    """The dataclass keyword arguments the panel's ``props`` hold for ``names`` (0 back to None
    for an optional integer)."""
    rename = rename or {}
    out = {}
    for s in declared(cls, names):
        if names is None and not s.panel:
            continue
        value = getattr(props, rename.get(s.name, s.name))
        if s.kind == "int" and s.optional and not value:
            value = None
        out[s.name] = value
    return out
