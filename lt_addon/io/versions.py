"""Format versions of every file a bake writes, and the one check every loader makes.

Each file says what it is (``format``) and in which version (``format_version``): in a JSON
document or header, an EXR's ``relight:metadata``, or an NPZ's ``format`` / ``format_version``
arrays. A loader calls :func:`check`, which refuses a newer version than this build reads in one
line (``InputError``: the CLI prints ``relight: error: ...``, the panel reports it). A file of
an earlier version without the field reads as version 1. The table of files is in
docs/bake-files.md.
"""

from __future__ import annotations

from ..errors import InputError

#: format -> the version this build writes and the newest it reads
FORMATS = {
    "relightable_textures.transport_texture": 1,      # <object>_transport_texture.json (T's header)
    "relightable_textures.albedo": 1,                 # <object>_albedo.exr
    "relightable_textures.transport_model": 1,        # <object>_transport_model.npz
    "relightable_textures.transport_preview": 1,      # <object>_preview_eigen/tables.exr
    "relightable_textures.transport_sparse_table": 1,  # <object>_preview_sparse_*.exr
    "relightable_textures.transport_sparse_atlas": 1,  # <object>_preview_transport.json
    "relightable_textures.block_viewport": 1,         # <object>_viewport_blocks.npz
    "relightable_textures.horizon_map": 7,            # <object>_horizons.npz (2: the
    #                                                   horizons may be coarser than the normals;
    #                                                   3: the upper edges are the footprint's
    #                                                   mean, with their spread; 4: the codes
    #                                                   start 10 degrees under the horizon --
    #                                                   older ones are recoded on load; 5: an
    #                                                   open band inside the interval, q's
    #                                                   planes 2 and 3, where a map has one;
    #                                                   6: where each azimuth gap's horizon
    #                                                   jumps, "cross", where a map has one;
    #                                                   7: the open bands' edges the
    #                                                   footprint's mean, their spreads
    #                                                   "band_spread", where a map has them)
    "relightable_textures.horizon_preview": 5,        # <object>_preview_horizons.png/.exr
    #                                                   (2: codes from 10 degrees under the
    #                                                   horizon, as horizon_map 4; 3: the
    #                                                   open bands' tiles after the others;
    #                                                   4: the gaps' crossings' tiles after
    #                                                   them; 5: the bands' edges' spreads
    #                                                   last)
    "relightable_textures.block_preview": 1,          # <object>_preview_block_eigen/tables.exr
    "relightable_textures.gathered_indirect": 1,      # <object>_indirect.npz
    "relightable_textures.gathered_indirect_preview": 1,  # <object>_preview_indirect_*.exr
    "relightable_textures.atlas": 1,                  # <object>_steerable_atlas.exr, indirect atlas
    "relightable_textures.commit_journal": 1,         # .relight-stage-*/.journal.json
}


#: the version of the bake reports (``<object>_steerable.json``, ``_transport.json``,
#: ``_materials.json``: what was baked, how, and its figures; the files they list carry their own)
REPORT_VERSION = 1


def version_of(fmt: str) -> int:
    """The version this build writes for ``fmt`` (1 for a format not in :data:`FORMATS`)."""
    return FORMATS.get(fmt, 1)


def stamp(fmt: str) -> dict:
    """``{"format": fmt, "format_version": N}`` to put into a file's header."""
    return {"format": fmt, "format_version": version_of(fmt)}


def check(meta: dict, fmt: str, path: str, what: str = "") -> None:
    """Refuse ``path`` in one line unless its header ``meta`` is ``fmt`` in a version this build
    reads."""
    found = meta.get("format")
    if found != fmt:
        raise InputError(f"{path} is not {what or 'a ' + fmt.rsplit('.', 1)[-1].replace('_', ' ')}"
                         f" file (format {found!r})")
    try:
        v = int(meta.get("format_version", 1))
    except (TypeError, ValueError):
        raise InputError(f"{path}: unreadable format_version {meta.get('format_version')!r}") \
            from None
    if v > version_of(fmt):
        raise InputError(f"{path}: {fmt} version {v} is newer than this version of Relightable "
                         f"Textures reads ({version_of(fmt)}); update the add-on")
