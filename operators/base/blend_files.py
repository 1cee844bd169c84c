"""Reading and writing .blend files for the CLI (bpy).

The relightable data of an object lives in ID custom properties (``obj["relightable_bakes"]``,
a list of dicts), not in registered PropertyGroups, so ``relight info`` can read it from the plain
``bpy`` module and from a Blender where the extension is not enabled.

Listing format (``relight info --json``)::

    {"file": str, "blender": "5.0.1", "sample": str | null, "sample_size": str | null,
     "objects": [{"name": str, "type": "MESH", "vertices": int, "faces": int,
                  "uv_maps": [str], "bakes": [ {"kind": str, "path": str, ...}, ... ]}]}

Each later bake verb appends one dict to ``bakes`` with at least ``kind`` (e.g.
``"steerable_texture"``, ``"eigentransport"``), ``path`` (relative to the .blend, Blender's
``//`` prefix) and ``created`` (ISO 8601 UTC).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time

import bpy

from ...lt_addon.io import atomic

BAKES_KEY = "relightable_bakes"


@contextlib.contextmanager
def blender_log_to_stderr():
    """Send what Blender itself prints to stdout (file reads/saves) to stderr for a while.

    The CLI's stdout then carries only its own output, so ``relight info --json`` pipes cleanly.
    """
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _fresh_session() -> None:
    """Replace the open file by an empty factory scene (keeps preferences and add-ons)."""
    with blender_log_to_stderr():
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


def save_atomically(path: str) -> None:
    """Save the open session as a copy at ``path``: write a temporary file beside it, then rename.

    A failure leaves ``path`` as it was (absent or the previous file) and no temporary behind.
    """
    # A fresh temporary name: Blender would keep a .blend1 backup of an existing file.
    with atomic.atomic_path(path) as tmp:
        save_copy(tmp)


def save_copy(tmp: str) -> None:
    """Save the open session as a copy at ``tmp`` (a temporary name the caller renames)."""
    with blender_log_to_stderr():
        result = bpy.ops.wm.save_as_mainfile(filepath=tmp, copy=True, check_existing=False)
    if "FINISHED" not in result or not os.path.exists(tmp) or not os.path.getsize(tmp):
        raise RuntimeError(f"Blender could not save {tmp}")


def write_sample_scene(name: str, size: str, path: str) -> dict:
    """Build sample scene ``name`` at ``size`` in a fresh session and save it to ``path``."""
    from ... import samples

    _fresh_session()
    info = samples.build(name, bpy.context.scene, size)
    obj = bpy.data.objects[info["relight_object"]]
    save_atomically(path)
    return {**info, "vertices": len(obj.data.vertices)}


def current_file() -> str:
    """Path of the open .blend, or '' when the session is unsaved."""
    return bpy.data.filepath


def _plain(value):
    """ID-property values (groups, arrays) as plain Python for JSON."""
    if hasattr(value, "to_dict"):
        return {k: _plain(v) for k, v in value.to_dict().items()}
    if hasattr(value, "to_list"):
        return [_plain(v) for v in value.to_list()]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def object_bakes(obj) -> list[dict]:
    """The bake records stored on ``obj`` (empty list when none)."""
    return _plain(obj.get(BAKES_KEY, [])) or []



def move_staged_paths(stage: str, target: str) -> int:
    """After a bake's files moved from its staging folder ``stage`` to ``target``
    (:mod:`...lt_addon.io.transaction`): point the session's data at them -- image file paths
    and the string custom properties (bake records, preview groups' report paths) of objects,
    materials, node groups, scenes and images. Returns how many values changed."""
    from ...lt_addon.io.transaction import rewrite_paths

    name = os.path.basename(os.path.normpath(stage))
    changed = 0
    for image in bpy.data.images:
        if name in image.filepath:
            image.filepath = rewrite_paths(image.filepath, stage, target)
            changed += 1
    for coll in (bpy.data.objects, bpy.data.materials, bpy.data.node_groups, bpy.data.scenes,
                 bpy.data.images, bpy.data.meshes):
        for idb in coll:
            for key in list(idb.keys()):
                try:
                    value = idb[key]
                except KeyError:
                    continue
                plain = _plain(value)
                if name not in repr(plain):
                    continue
                idb[key] = rewrite_paths(plain, stage, target)
                changed += 1
    return changed


def _id_value(v):
    """``v`` as an ID property can hold it: ID properties keep 32-bit integers, so a larger one
    (a 2048^2 bake's bytes: 3.2 GB) is kept as a float (exact below 2^53)."""
    if isinstance(v, int) and not isinstance(v, bool) and not -2 ** 31 <= v < 2 ** 31:
        return float(v)
    return v


def record_kind(obj, kind: str, file_path: str, fields: dict) -> None:
    """Replace the object's bake record of ``kind`` (kept as an ID custom property), with the
    file path relative to the .blend when it is saved."""
    try:
        path = bpy.path.relpath(file_path) if bpy.data.filepath else os.path.abspath(file_path)
    except ValueError:  # another drive on Windows
        path = os.path.abspath(file_path)
    entry = {"kind": kind, "path": path,
             "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
             **{k: _id_value(v) for k, v in fields.items()}}
    bakes = [b for b in object_bakes(obj) if b.get("kind") != kind]
    obj[BAKES_KEY] = bakes + [entry]


def bake_file(obj, kind: str, what: str) -> str:
    """Absolute path of the file behind ``obj``'s latest bake record of ``kind``.

    Raises ValueError (no such bake) or FileNotFoundError (the file moved), both naming the
    command that fixes it.
    """
    records = [b for b in object_bakes(obj) if b.get("kind") == kind]
    if not records:
        raise ValueError(f"{obj.name} has no {what} bake; run the bake first")
    path = bpy.path.abspath(records[-1]["path"])
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{obj.name}'s {what} file is missing: {path} "
                                "(moved or deleted? re-bake or restore the file)")
    return path


def relightable_listing(path: str) -> dict:
    """Open ``path`` (unless it is already the open file) and describe its relightable data."""
    if os.path.abspath(path) != os.path.abspath(bpy.data.filepath or "<unsaved>"):
        with blender_log_to_stderr():
            bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    scene = bpy.context.scene
    objects = []
    for obj in sorted(bpy.data.objects, key=lambda o: o.name):
        if obj.type != "MESH":
            continue
        mesh = obj.data
        objects.append({
            "name": obj.name,
            "type": obj.type,
            "vertices": len(mesh.vertices),
            "faces": len(mesh.polygons),
            "uv_maps": [uv.name for uv in mesh.uv_layers],
            "bakes": object_bakes(obj),
        })
    return {
        "file": os.path.abspath(path),
        "blender": bpy.app.version_string,
        "sample": scene.get("relight_sample"),
        "sample_size": scene.get("relight_sample_size"),
        "objects": objects,
    }


def format_listing(listing: dict) -> str:
    """Human-readable form of :func:`relightable_listing`."""
    head = f"{listing['file']} (Blender {listing['blender']}"
    if listing["sample"]:
        head += f", sample scene {listing['sample']} at size {listing['sample_size']}"
    lines = [head + ")"]
    if not listing["objects"]:
        lines.append("  no mesh objects")
    for o in listing["objects"]:
        uv = ", ".join(o["uv_maps"]) or "no UV map"
        lines.append(f"  {o['name']}: {o['vertices']} vertices, {o['faces']} faces, UV: {uv}")
        if not o["bakes"]:
            lines.append("    no relightable data")
        for b in o["bakes"]:
            extra = ", ".join(f"{k}={v}" for k, v in b.items() if k not in ("kind", "path"))
            lines.append(f"    {b.get('kind', '?')}: {b.get('path', '?')}" + (f" ({extra})" if extra else ""))
    return "\n".join(lines)


def activate_scene_of(obj, path: str) -> None:
    """Make the scene holding ``obj`` the context scene: a file saved with another scene active
    (e.g. after *Add Sample Scene*) must still bake the object where it lives. Raises
    BakeInputError (one line) when that cannot be done."""
    from .cycles_bake import BakeInputError

    if obj.name in bpy.context.view_layer.objects:
        return
    homes = list(obj.users_scene)
    if not homes:
        raise BakeInputError(f"object {obj.name!r} is in no scene of {path}; link it to a "
                             "scene first")
    wm = bpy.context.window_manager
    window = bpy.context.window or (wm.windows[0] if wm.windows else None)
    if window is None:
        raise BakeInputError(f"object {obj.name!r} is in scene {homes[0].name!r}, not the "
                             f"active one, and {path} has no window to switch scenes; save it "
                             "with that scene active")
    window.scene = homes[0]
    if obj.name not in bpy.context.view_layer.objects:
        raise BakeInputError(f"object {obj.name!r} is not in view layer "
                             f"{bpy.context.view_layer.name!r} of scene {homes[0].name!r} (its "
                             "collection is excluded); include it")
