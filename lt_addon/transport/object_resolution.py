"""Per-object texture sizes of one transport bake (issue 33: large receivers at low suns).

The ground under an object is where a low sun's long shadow falls, and it is usually much
larger than the object: at one shared texture size its shadows get few texels. A bake may give
each object its own side: the objects are grouped by size and each group is baked as today
(every object of the scene still casts shadows on every group), into the same output folder.

Pure logic: parsing ``NAME=SIDE`` and the grouping. The bpy layer runs the groups
(``operators/bakes/texture_transport.bake_job``).
"""

from __future__ import annotations

from ..errors import InputError

#: texture sides a transport bake takes (TransportTextureSettings.validate's range)
SIDES = (4, 8192)


class ResolutionError(InputError):
    """A per-object resolution that cannot be used: the project's one input error (the CLI
    prints it as one line, the panel's operators report it)."""


def parse(spec: str) -> tuple[str, int]:
    """``"NAME=SIDE"`` -> (NAME, SIDE); the name may itself hold ``=`` (the last one splits)."""
    name, sep, side = spec.rpartition("=")
    if not sep or not name:
        raise ResolutionError(f"--object-resolution takes NAME=SIDE (e.g. Ground=1024), "
                              f"got {spec!r}")
    try:
        value = int(side)
    except ValueError:
        raise ResolutionError(f"--object-resolution {spec}: the side must be a whole number of "
                              "texels") from None
    check(name, value)
    return name, value


def check(name: str, side: int) -> None:
    if not SIDES[0] <= side <= SIDES[1]:
        raise ResolutionError(f"the resolution of {name} must be in {SIDES[0]}..{SIDES[1]} "
                              f"texels, got {side}")


def groups(names: list, default: int, sides: dict | None) -> list:
    """The bake's groups: ``[(side, [indices into names]), ...]``, the largest side first (its
    cost shows first in the progress), objects in their given order within a group.

    ``sides``: {object name: side}; objects not in it (or with 0) take ``default``. A name in
    ``sides`` that is not baked is refused: it is a typo the user would not see otherwise."""
    sides = {k: int(v) for k, v in (sides or {}).items()}
    unknown = sorted(set(sides) - set(names))
    if unknown:
        raise ResolutionError(f"--object-resolution names {', '.join(unknown)}, which is not "
                              f"baked (baked: {', '.join(names)})")
    by_side: dict = {}
    for i, name in enumerate(names):
        side = sides.get(name) or default
        check(name, side)
        by_side.setdefault(side, []).append(i)
    return sorted(by_side.items(), key=lambda kv: -kv[0])
