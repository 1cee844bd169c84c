"""EEVEE renders (F12) keep the user's materials while the preview shows (issue 57) (bpy).

The preview's Material Output targets EEVEE, so Material Preview and EEVEE's Rendered view show
it while Cycles never does. An EEVEE *render* would show it too: there is no node that tells a
viewport from a final render. So for the length of an EEVEE render the preview outputs step
aside (``render_init``) and come back when it ends (``render_complete`` / ``render_cancel``).

Render handlers run on the thread that renders. That is the main thread for
``bpy.ops.render.render()`` from a script, ``blender -b … -f``, and the tests; for F12 in the
UI it is the render job's thread, where changing data the viewport draws can crash Blender
unless the interface is locked (Blender's documented rule: *Render ▸ Lock Interface*,
``RenderSettings.use_lock_interface``). So the preview steps aside on the main thread, or
with the interface locked; otherwise it is left alone. A bake from the panel on an EEVEE scene
locks the interface (and says so; Remove Preview unlocks it again), and the panel offers the
toggle whenever the preview shows and it is off.
"""

from __future__ import annotations

import threading

import bpy

from ..base.compat import EEVEE_ENGINE
from . import preview_nodes

#: (material, kind) pairs taken away for the render in progress
_gone: list = []


def can_step_aside(scene) -> bool:
    """Whether an EEVEE render of ``scene`` started now may change materials safely: on the
    main thread, or with the interface locked."""
    return (threading.current_thread() is threading.main_thread()
            or bool(scene.render.use_lock_interface))


#: on the scene: a bake turned Lock Interface on (Remove Preview turns it back off)
LOCKED_KEY = "relight_locked_interface"


def lock_for_renders(scene) -> bool:
    """After a bake installed a preview from the panel: with EEVEE as the render engine and the
    interface not locked during renders, lock it (so F12 from the UI may swap the preview out
    safely) and remember that we did. Returns whether it changed anything."""
    if scene.render.engine != EEVEE_ENGINE or scene.render.use_lock_interface:
        return False
    scene.render.use_lock_interface = True
    scene[LOCKED_KEY] = True
    return True


def unlock_after_previews(scene) -> bool:
    """Remove Preview: when no material shows a preview any more and a bake locked the
    interface (and it is still locked), unlock it. Returns whether it changed anything."""
    if not scene.get(LOCKED_KEY) or preview_nodes.any_preview():
        return False
    del scene[LOCKED_KEY]
    if not scene.render.use_lock_interface:
        return False
    scene.render.use_lock_interface = False
    return True


@bpy.app.handlers.persistent
def _on_render_init(scene, *_args) -> None:
    if scene is None or scene.render.engine != EEVEE_ENGINE or _gone:
        return
    if can_step_aside(scene):
        _gone.extend(preview_nodes.step_aside_for_render())


@bpy.app.handlers.persistent
def _on_render_end(*_args) -> None:
    gone = list(_gone)
    _gone.clear()
    if gone:
        preview_nodes.step_back(gone)


_HANDLERS = (("render_init", _on_render_init), ("render_complete", _on_render_end),
             ("render_cancel", _on_render_end))


def register() -> None:
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def unregister() -> None:
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn in handlers:
            handlers.remove(fn)
    _on_render_end()
