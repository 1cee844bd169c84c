"""Settings declared once: a bake's settings dataclass says, per field, its default, help text,
range and choices, and everything a user sets it through is made from that.

A field declared with :func:`setting` carries its description in ``dataclasses`` metadata;
:func:`declared` reads it back as :class:`Setting` rows. From them the bpy layer makes the
panel's properties (``operators/ui/settings_props.py``), the CLI its options
(``operators/cli/common.py``: ``add_setting_options``) and the panel's *Run On* its command
line (:func:`to_argv`), so a new setting, a new range or a better help text is written in one
place. Fields whose panel form differs from the dataclass's (a count of directions where the
CLI takes a ``hemi:N`` spec) keep their own panel property; their CLI option and argv still come
from here.

Validation stays with each dataclass (``validate()``), which knows the cross-field rules and
says them in its own words; it ends with :func:`check_ranges`, so the declared ranges and
choices are enforced whatever set the value.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

_KEY = "relightable_textures.setting"


def setting(default=dataclasses.MISSING, *, help: str, label: str = "", lo=None, hi=None,
            choices=None, flag: str = "", metavar: str = "", panel: bool = True, soft=None,
            default_factory=dataclasses.MISSING):
    """A dataclass field with its user-facing description.

    ``label``: the panel's name for it (default: the field name, capitalised); ``lo``/``hi``:
    its range (inclusive); ``choices``: the allowed values, as ``(value, label, description)``
    rows or plain values; ``flag``: its CLI option (default ``--field-name``); ``panel``: False
    when the panel shows it in another form (it then declares its own property); ``soft``:
    ``(lo, hi)`` of the panel's slider where the useful range is narrower than the valid one."""
    rows = None
    if choices is not None:
        rows = tuple(c if isinstance(c, tuple) else (c, str(c).capitalize(), "")
                     for c in choices)
    meta = {_KEY: {"help": help, "label": label, "lo": lo, "hi": hi, "choices": rows,
                   "flag": flag, "metavar": metavar, "panel": panel, "soft": soft}}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@dataclass(frozen=True)
class Setting:
    """One declared field: what the panel, the CLI and the argv builder need."""
    name: str
    kind: str                   # "int", "float", "str", "bool"
    default: object
    optional: bool              # None is allowed (the CLI's "not given", a preset's choice)
    help: str
    label: str
    lo: object
    hi: object
    choices: tuple | None       # ((value, label, description), ...)
    flag: str
    metavar: str
    panel: bool
    required: bool = False      # no default: the CLI option is required
    soft: tuple | None = None   # the panel slider's (lo, hi), when narrower than the range

    def parse(self, text: str):
        """A value of this setting from its command-line text."""
        return {"int": int, "float": float, "bool": _bool}.get(self.kind, str)(text)

    def format(self, value) -> str:
        """The command-line text of ``value`` (what :meth:`parse` reads back)."""
        if isinstance(value, float):
            return repr(value) if value != int(value) else f"{value:g}"
        return str(value)


def _bool(text: str) -> bool:
    if text.lower() in ("1", "true", "yes", "on"):
        return True
    if text.lower() in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"not a boolean: {text!r}")


def _kind(annotation) -> tuple:
    """("int" | "float" | "str" | "bool" | "other", optional) of a field's annotation (a string
    under ``from __future__ import annotations``)."""
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__",
                                                                 str(annotation))
    parts = [p.strip() for p in text.split("|")]
    optional = "None" in parts
    base = next((p for p in parts if p != "None"), "other")
    return (base if base in ("int", "float", "str", "bool") else "other"), optional


def declared(cls, names=None) -> list:
    """The :class:`Setting` rows of ``cls``'s declared fields (in ``names``' order when given;
    a name that is not declared raises KeyError, so a typo cannot drop an option)."""
    fields = {f.name: f for f in dataclasses.fields(cls) if _KEY in f.metadata}
    order = list(fields) if names is None else list(names)
    out = []
    for name in order:
        f = fields[name]
        meta = f.metadata[_KEY]
        kind, optional = _kind(f.type)
        required = (f.default is dataclasses.MISSING
                    and f.default_factory is dataclasses.MISSING)
        default = (f.default if f.default is not dataclasses.MISSING else
                   f.default_factory() if f.default_factory is not dataclasses.MISSING
                   else None)
        out.append(Setting(
            name=name, kind=kind, default=default, optional=optional, help=meta["help"],
            label=meta["label"] or name.replace("_", " ").title(), lo=meta["lo"], hi=meta["hi"],
            choices=meta["choices"], flag=meta["flag"] or "--" + name.replace("_", "-"),
            metavar=meta["metavar"], panel=meta["panel"], required=required,
            soft=meta.get("soft")))
    return out


def to_argv(settings, names=None, *, skip=()) -> list:
    """The command-line arguments that give ``settings``' declared fields their values (None
    left out: the CLI then takes its default or the preset's), e.g. for the panel's Run On."""
    args = []
    for s in declared(type(settings), names):
        value = getattr(settings, s.name)
        if s.name in skip or value is None:
            continue
        if s.kind == "bool":
            if value:
                args.append(s.flag)
            continue
        args += [s.flag, s.format(value)]
    return args


def range_errors(settings) -> list:
    """Declared ranges and choices ``settings`` breaks, as readable lines (empty: none)."""
    out = []
    for s in declared(type(settings)):
        value = getattr(settings, s.name)
        if value is None:
            continue
        if s.choices and value not in [c[0] for c in s.choices]:
            out.append(f"{s.name} must be one of {', '.join(str(c[0]) for c in s.choices)}, "
                       f"got {value!r}")
        if s.lo is not None and value < s.lo or s.hi is not None and value > s.hi:
            out.append(f"{s.name} must be in {s.lo}..{s.hi}, got {value}")
    return out


def check_ranges(settings) -> None:
    """Raise :class:`.errors.InputError` with the first declared range or choice ``settings``
    breaks: each dataclass's ``validate()`` ends with it, so the declared range is the one
    enforced, whatever set the value."""
    from .errors import InputError

    errors = range_errors(settings)
    if errors:
        raise InputError(errors[0])
