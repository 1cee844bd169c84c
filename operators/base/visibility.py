"""Whether an object is in the render, as Cycles has it (bpy; issue 59).

An object renders when its own camera icon is on (``hide_render`` off) and at least one of the
view layer's collections holding it is reached from the scene's collection through collections
that are neither excluded from the view layer (``LayerCollection.exclude``) nor hidden from
render (``Collection.hide_render``). The viewport's eye and monitor icons do not matter to a
render. docs/bake-files.md "The scene's visibility flags" says what each flag does in a bake.
"""

from __future__ import annotations


def _paths(layer_collection, obj, path=()):
    """Every chain of layer collections from the view layer's root to one holding ``obj``."""
    path = path + (layer_collection,)
    if obj.name in layer_collection.collection.objects:
        yield path
    for child in layer_collection.children:
        yield from _paths(child, obj, path)


def render_hidden(obj, view_layer=None) -> str | None:
    """Why ``obj`` is not in the render of ``view_layer`` (the context's by default), as the
    end of a sentence that starts with its name, or None when it renders."""
    import bpy

    if obj.hide_render:
        return "is hidden from render (its camera icon is off)"
    view_layer = view_layer or bpy.context.view_layer
    blocked = []
    for path in _paths(view_layer.layer_collection, obj):
        why = None
        for lc in path[1:]:          # the root is the scene's collection: no flags of its own
            if lc.exclude:
                why = f"collection {lc.name!r}, which is excluded from the view layer"
            elif lc.collection.hide_render:
                why = f"collection {lc.name!r}, which is hidden from render"
            if why:
                break
        if why is None:
            return None
        blocked.append((path[-1].name, why))
    if not blocked:
        return f"is not in view layer {view_layer.name!r}"
    holder, why = blocked[0]
    if holder == why.split("'")[1]:
        return f"is in {why}"
    return f"is in collection {holder!r}, inside {why}"


def in_render(obj, view_layer=None) -> bool:
    """Whether ``obj`` is in the render (:func:`render_hidden`)."""
    return render_hidden(obj, view_layer) is None


def rendered_names(view_layer=None) -> set:
    """The names of every object in the render of ``view_layer`` (the context's by default):
    :func:`render_hidden` for a whole scene in one walk of its collections."""
    import bpy

    view_layer = view_layer or bpy.context.view_layer
    names, stack = set(), [view_layer.layer_collection]
    while stack:
        lc = stack.pop()
        names.update(o.name for o in lc.collection.objects if not o.hide_render)
        stack.extend(c for c in lc.children if not c.exclude and not c.collection.hide_render)
    return names


def baked_as_surface(obj) -> str | None:
    """The one-line note of a baked holdout or shadow catcher (its flag cleared for the bake:
    :meth:`.cycles_bake.EnvironmentBake._bake_as_surfaces`), or None."""
    for flag, what in (("is_shadow_catcher", "a shadow catcher"), ("is_holdout", "a holdout")):
        if getattr(obj, flag, False):
            return (f"{obj.name} is {what}: baked as a plain surface, lit and shadowed as the "
                    "other objects see it (Cycles' own bake of it is black)")
    return None


def baked_notes(obj) -> list:
    """The one-line notes of a baked object's render flags that the bake does not reproduce on
    the object itself: a holdout or shadow catcher (:func:`baked_as_surface`), and an object
    that casts no shadow (``visible_shadow`` off): the ray bake leaves it out of every shadow
    ray, yet on the statue sample its own texture measured 0.44 / 0.22 from Cycles' bake of it
    (0.12 / 0.14 with its shadow on; issue 59, not modelled), so the report says it."""
    notes = [n for n in (baked_as_surface(obj),) if n]
    if not getattr(obj, "visible_shadow", True):
        notes.append(f"{obj.name} casts no shadow (Ray Visibility > Shadow off): its own texture "
                     "is not as Cycles bakes it with that flag (measured up to 3.7x "
                     "further from Cycles than with its shadow on); turn the flag on for the "
                     "bake if its own shading matters")
    return notes

