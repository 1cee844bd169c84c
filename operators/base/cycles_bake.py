"""Cycles texture bakes of one object under a sequence of environment images (bpy).

:class:`EnvironmentBake` rigs the scene for bakes lit only by an equirectangular world image,
bakes into a float image through the object's UV map, and restores everything it touched on
exit -- world, Cycles settings, lamp visibility, selection, material nodes -- whether the bakes
finished, failed or were cancelled. It never writes to the user's images: the target image is
its own and is removed on exit.

What is baked (``mode``):

* ``"radiance"`` (default, what the paper bakes): DIFFUSE bake with direct + indirect + colour,
  i.e. outgoing diffuse radiance ``albedo * E / pi`` with interreflection included.
* ``"irradiance"``: DIFFUSE without the colour pass, ``E / pi`` (direct + indirect), so the
  albedo texture can be changed afterwards. Interreflected light still carries the albedo of
  the bounce surfaces at bake time.
"""

from __future__ import annotations

import time

import bpy
import numpy as np

from ...lt_addon.errors import InputError
from . import cycles_device
from .compat import ensure_node_tree
from .meshes import (color_attribute, corner_vertices, image_pixels, polygon_arrays,
                     set_image_pixels)

BAKE_MODES = ("radiance", "irradiance")
#: Light paths a bake keeps: everything, direct only, indirect only, or the diffuse colour alone
#: (the albedo texture: no light at all).
BAKE_PASSES = ("all", "direct", "indirect", "color")
#: World light sampling: "importance" (an importance map of the environment image: ~3x lower
#: noise at equal samples on the steerable lobes, unbiased, linear in the light in expectation)
#: or "none" (BSDF sampling only: with a fixed seed the bake is *exactly* linear in the image).
WORLD_SAMPLING = ("importance", "none")
_PREFIX = "RelightBake"


#: The object or settings cannot be baked; the message says what to change. The core's own
#: error class (its settings and bundle readers raise it), under the bpy layer's name.
BakeInputError = InputError


def dark_material_reason(material) -> str | None:
    """Why a material's diffuse colour is (near) zero, or None: its active output's surface is
    a Principled BSDF with an unlinked black Base Color or Metallic 1, or a Diffuse BSDF with an
    unlinked black Color. Materials driven by textures or other nodes are not judged."""
    tree = material.node_tree  # Blender 5: every material has a node tree (use_nodes is going)
    if tree is None:
        return "black" if max(material.diffuse_color[:3]) < 1e-3 else None
    out = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"
                and n.is_active_output), None)
    if out is None or not out.inputs["Surface"].is_linked:
        return None
    node = out.inputs["Surface"].links[0].from_node
    if node.bl_idname == "ShaderNodeBsdfPrincipled":
        metal = node.inputs["Metallic"]
        if not metal.is_linked and metal.default_value >= 0.999:
            return "fully metallic"
        color = node.inputs["Base Color"]
    elif node.bl_idname == "ShaderNodeBsdfDiffuse":
        color = node.inputs["Color"]
    else:
        return None
    if not color.is_linked and max(color.default_value[:3]) < 1e-3:
        return "black"
    return None


def available_memory_bytes() -> int:
    """Physical memory available now: Linux's ``MemAvailable`` (free memory and the page cache
    the kernel can drop), else sysconf's free pages (macOS); 16 GiB where neither can be read.
    Free pages alone undercount after a large bake: T's pages stay cached (after a 4096^2 bake
    13.0 GiB were free of 23.0 GiB available, and the next bake was refused)."""
    import os

    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return 16 * 2 ** 30


def _reports_to_stderr():
    """Operator reports Blender prints through Python's stdout, sent to stderr: the CLI's stdout
    carries only its results."""
    import contextlib
    import sys

    return contextlib.redirect_stdout(sys.stderr)


def check_memory(need_bytes: int, what: str, fix: str) -> None:
    """Refuse up front when ``need_bytes`` exceeds 80% of the memory available now."""
    have = available_memory_bytes()
    if need_bytes > 0.8 * have:
        raise BakeInputError(f"{what} needs {_size(need_bytes)} but only {_size(have)} of "
                             f"memory is available; {fix}")


def _size(nbytes: float) -> str:
    """``1.5 GiB`` / ``12.0 MiB`` / ``300 bytes``: readable at any scale."""
    for unit, scale in (("GiB", 2 ** 30), ("MiB", 2 ** 20), ("KiB", 2 ** 10)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{int(nbytes)} bytes"


def check_bakeable(obj, need_uv: bool = True) -> None:
    """Raise :class:`BakeInputError` unless ``obj`` is a mesh object in the render
    (:func:`.visibility.render_hidden`), with a UV map if asked."""
    if obj is None:
        raise BakeInputError("no object given")
    if obj.type != "MESH":
        kind = obj.type.lower().replace("_", " ")
        article = "an" if kind[:1] in "aeiou" else "a"
        raise BakeInputError(f"{obj.name} is {article} {kind}, not a mesh")
    from .visibility import render_hidden

    hidden = render_hidden(obj)
    if hidden:   # Cycles refuses to bake it; the rays would bake it with no shadow of its own
        raise BakeInputError(f"{obj.name} {hidden}: Cycles would not bake it; enable it or "
                             "leave it out")
    if need_uv:
        from .meshes import bake_uv_name

        bake_uv_name(obj)   # no UV map, or not the one chosen: refused in one line
    if not obj.data.polygons:
        raise BakeInputError(f"{obj.name} has no faces to bake")
    _check_area(obj, need_uv)


def _check_area(obj, need_uv: bool) -> None:
    """Refuse a mesh whose faces have no area, or whose bake UV map (:func:`.meshes.bake_uv_name`)
    has none (every UV on one point or one line): either bakes nothing, and used to give an
    all-zero texture with exit 0 or a raw ``ValueError`` from deep in the bake (issue 56). The
    mesh as stored: a modifier that makes area from none is rare enough to be told to apply
    it."""
    from .meshes import bake_uv_name, uv_corners

    mesh = obj.data
    area, start, total = polygon_arrays(mesh)
    if not np.isfinite(area).all() or float(area.sum()) <= 0.0:
        raise BakeInputError(f"{obj.name}: its faces have no area (every face is degenerate: "
                             "a point or a line); nothing to bake")
    if need_uv and mesh.uv_layers:
        uv = uv_corners(mesh, bake_uv_name(obj))
        nxt = np.arange(len(uv)) + 1   # each corner's next corner around its face
        last = start + total - 1
        nxt[last] = start
        cross = uv[:, 0] * uv[nxt, 1] - uv[nxt, 0] * uv[:, 1]   # shoelace terms
        uv_area = np.abs(np.add.reduceat(cross, start)) / 2 if len(start) else np.zeros(0)
        if not np.isfinite(uv).all() or float(uv_area.sum()) <= 1e-12:
            raise BakeInputError(f"{obj.name}: its UV map covers no area (every UV on one "
                                 "point or line); unwrap it (UV > Unwrap) before baking")


def _face_of_corner(mesh) -> np.ndarray:
    """The face of every corner (loop), shape (L,), int64."""
    area, starts, sizes = polygon_arrays(mesh)
    by_start = np.argsort(starts, kind="stable")  # a face's loops are contiguous
    return np.repeat(by_start, sizes[by_start])


def _corners_with_area(mesh) -> np.ndarray:
    """bool, shape (L,): the corners of faces of positive area (see :func:`_vertices_with_area`)."""
    if len(mesh.polygons) == 0:
        return np.zeros(len(mesh.loops), dtype=bool)
    return polygon_arrays(mesh)[0][_face_of_corner(mesh)] > 0


def _vertices_with_area(mesh) -> np.ndarray:
    """bool, shape (V,): the vertices of at least one face of positive area.

    The others (loose vertices, corners of zero-area faces only) have no surface to receive
    light and get 0 by definition: Blender 5.0's Cycles bakes them to 0, 5.2's shades a
    zero-area triangle with a made-up normal (measured: cosine of an upward normal)."""
    n_faces = len(mesh.polygons)
    lit = np.zeros(len(mesh.vertices), dtype=bool)
    if n_faces == 0:
        return lit
    lit[corner_vertices(mesh)[_corners_with_area(mesh)]] = True
    return lit


class SceneChanges:
    """Base of the context managers that change the scene for a while: ``_setup()`` makes the
    changes, recording an undo callable in ``self._restore`` for each and every datablock it
    creates as ``(collection, block)`` in ``self._created``; on exit (or a failed setup) they
    are undone in reverse order, all of them even when one fails."""

    what = "the scene"

    def _setup(self):
        raise NotImplementedError

    def __enter__(self):
        try:
            self._setup()
        except BaseException:
            self._teardown()
            raise
        return self

    def _teardown(self):
        errors = []
        while self._restore:
            try:
                self._restore.pop()()
            except Exception as exc:  # keep restoring the rest
                errors.append(exc)
        while self._created:
            collection, block = self._created.pop()
            try:
                collection.remove(block)
            except Exception as exc:
                errors.append(exc)
        if errors:
            raise RuntimeError(f"could not fully restore {self.what}: {errors[0]}")

    def __exit__(self, exc_type, exc, tb):
        try:
            self._teardown()
        except RuntimeError:
            if exc_type is None:
                raise
            # keep the original error visible; the restore problem is secondary
        return False


class EnvironmentBake(SceneChanges):
    """Context manager: bake ``obj`` under environment images, restoring the scene on exit.

    Parameters
    ----------
    scene : bpy.types.Scene
    obj : bpy.types.Object or list of them
        Mesh(es) with a UV map (the bake's map, :func:`.meshes.bake_uv_name`: the active one
        unless one was chosen; made active for the bake and named to Cycles). Several objects are baked
        in the same Cycles calls, each into its own texture or per-vertex colour attribute
        (:meth:`bake_all`), so shadows and light fall between them; for textures, a material
        shared by two of them is replaced by a temporary copy on the second during the bake.
    resolution : int or None
        Baked texture side in texels; ``None`` bakes per vertex instead (into a temporary
        FLOAT_COLOR attribute; no UV map needed).
    domain : {"POINT", "CORNER"}
        Per-vertex bakes: one value per vertex (Cycles averages the vertex's corners), or one
        per face corner (a hard edge keeps a value per side).
    samples : int
        Cycles samples per texel (fixed seed ``seed``, no adaptive sampling, no denoiser).
    bounces : int
        Diffuse (and total) bounce limit; 0 = direct light only.
    env_size : (int, int)
        ``(height, width)`` of the equirectangular environment images passed to :meth:`bake`.
    mode : {"radiance", "irradiance"}
        See the module docstring.
    margin : int
        Texel margin Cycles extends beyond UV islands (Blender's Extend margin).
    world_sampling : {"importance", "none"}
        See :data:`WORLD_SAMPLING`.
    importance_map_size : int
        Resolution of the world importance map (Cycles' ``sample_map_resolution``).
    glossy_bounces : int
        Cycles' glossy bounce limit (0: light is not carried on after a glossy reflection;
        the material bakes' truths of metallic edits need their bounce count).
    """

    def __init__(self, scene, obj, resolution: int, samples: int, bounces: int,
                 env_size: tuple[int, int], mode: str = "radiance", seed: int = 0,
                 margin: int = 4, world_sampling: str = "importance", importance_map_size: int = 256,
                 passes: str = "all", domain: str = "POINT", glossy_bounces: int = 0):
        self.per_vertex = resolution is None
        self.glossy_bounces = int(glossy_bounces)   # 0: a glossy closure ends the path
        if domain not in ("POINT", "CORNER"):
            raise BakeInputError(f"domain must be POINT or CORNER, got {domain!r}")
        self.domain = domain
        self.objects = list(obj) if isinstance(obj, (list, tuple)) else [obj]
        if not self.objects:
            raise BakeInputError("no object given")
        for o in self.objects:
            check_bakeable(o, need_uv=not self.per_vertex)
        meshes = [o.data for o in self.objects]
        if len({id(m) for m in meshes}) != len(meshes):
            raise BakeInputError("two of the objects share one mesh; bake one of them, or make "
                                 "the mesh single-user (Object > Relations > Make Single User)")
        if passes not in BAKE_PASSES:
            raise BakeInputError(f"passes must be one of {BAKE_PASSES}, got {passes!r}")
        self.passes = passes
        obj = self.objects[0]
        if mode not in BAKE_MODES:
            raise BakeInputError(f"mode must be one of {BAKE_MODES}, got {mode!r}")
        if not self.per_vertex and not 1 <= resolution <= 16384:
            raise BakeInputError(f"resolution must be in 1..16384, got {resolution}")
        if samples < 1 or bounces < 0:
            raise BakeInputError(f"need samples >= 1 and bounces >= 0, got {samples}, {bounces}")
        self.scene, self.obj = scene, obj
        self.resolution, self.samples, self.bounces = resolution, samples, bounces
        self.env_size, self.mode, self.seed, self.margin = tuple(env_size), mode, seed, margin
        if world_sampling not in WORLD_SAMPLING:
            raise BakeInputError(f"world_sampling must be one of {WORLD_SAMPLING}, got {world_sampling!r}")
        self.world_sampling = world_sampling
        self.importance_map_size = importance_map_size
        self.bake_seconds = 0.0  # wall time inside bpy.ops.object.bake
        self.bake_calls = 0
        self._restore = []  # callables run in reverse order on exit
        self._created = []  # (collection, datablock) removed on exit

    # -- setup -----------------------------------------------------------------------------------
    def _save_attr(self, owner, name, value):
        old = getattr(owner, name)
        self._restore.append(lambda: setattr(owner, name, old))
        setattr(owner, name, value)

    what = "the scene after baking"

    def _setup(self):
        scene = self.scene
        cyc = scene.cycles
        self._save_attr(scene.render, "engine", "CYCLES")
        # the device the bake was asked to use (cycles_device.use; the CPU if none was chosen)
        self.device = cycles_device.current()
        cycles_device.applied(scene, self.device, self._save_attr)
        if self.device.threads:   # --threads N: Cycles on N threads (restored after)
            self._save_attr(scene.render, "threads_mode", "FIXED")
            self._save_attr(scene.render, "threads", int(self.device.threads))
        if cycles_device.blas_policy():   # BLAS idle at one thread while Cycles has the cores
            from ...lt_addon import blas_threads

            limit = blas_threads.limited(1)
            limit.__enter__()
            self._restore.append(lambda: limit.__exit__(None, None, None))
        for name, value in (("samples", self.samples), ("seed", self.seed),
                            ("use_animated_seed", False), ("use_adaptive_sampling", False),
                            ("use_denoising", False), ("sample_clamp_direct", 0.0),
                            ("sample_clamp_indirect", 0.0), ("max_bounces", self.bounces),
                            ("diffuse_bounces", self.bounces), ("glossy_bounces", self.glossy_bounces),
                            ("transmission_bounces", 0), ("volume_bounces", 0)):
            self._save_attr(cyc, name, value)
        self._save_attr(cyc, "sampling_pattern", "TABULATED_SOBOL")  # 4.x's AUTOMATIC: blue noise
        bake = scene.render.bake
        self._save_attr(bake, "use_pass_direct", self.passes in ("all", "direct"))
        self._save_attr(bake, "use_pass_indirect", self.passes in ("all", "indirect"))
        self._save_attr(bake, "use_pass_color", self.mode == "radiance" or self.passes == "color")
        self._save_attr(bake, "margin", self.margin)
        # Extend (Blender's IMB_filter_extend): a margin the ray bake reproduces exactly
        # (lt_addon/rays/texels.py); the default Adjacent Faces samples across UV seams in 3D
        self._save_attr(bake, "margin_type", "EXTEND")
        self._save_attr(bake, "target", "VERTEX_COLORS" if self.per_vertex else "IMAGE_TEXTURES")
        self._save_attr(bake, "use_selected_to_active", False)

        # Lamps would add light the basis does not know about: hide them from render.
        for lamp in scene.objects:
            if lamp.type == "LIGHT" and not lamp.hide_render:
                self._save_attr(lamp, "hide_render", True)

        # A world lit only by our float environment image, with world importance sampling off
        # so the bake is exactly linear in the image (negative texels included).
        h, w = self.env_size
        self.env_image = self._new_image(f"{_PREFIX}Environment", w, h)
        world = bpy.data.worlds.new(f"{_PREFIX}World")
        self._created.append((bpy.data.worlds, world))
        world.cycles.sampling_method = "MANUAL" if self.world_sampling == "importance" else "NONE"
        world.cycles.sample_map_resolution = self.importance_map_size
        nodes, links = ensure_node_tree(world).nodes, world.node_tree.links
        for node in list(nodes):
            nodes.remove(node)
        tex = nodes.new("ShaderNodeTexEnvironment")
        tex.image = self.env_image
        tex.interpolation = "Linear"
        background = nodes.new("ShaderNodeBackground")
        background.inputs["Strength"].default_value = 1.0
        out = nodes.new("ShaderNodeOutputWorld")
        links.new(tex.outputs["Color"], background.inputs["Color"])
        links.new(background.outputs["Background"], out.inputs["Surface"])
        self._save_attr(scene, "world", world)

        self._bypass_previews()
        for o in self.objects:
            if not o.material_slots or not any(s.material for s in o.material_slots):
                mat = bpy.data.materials.new(f"{_PREFIX}DefaultMaterial")
                self._created.append((bpy.data.materials, mat))
                o.data.materials.append(mat)
                self._restore.append(
                    lambda m=o.data: m.materials.pop(index=len(m.materials) - 1))
            if self.mode == "irradiance" and self.passes != "color":
                self._whiten_dark_materials(o)
        if self.per_vertex:
            self.targets = [self._setup_vertex_target(o) for o in self.objects]
            self.target = self.targets[0]
        else:
            self._unshare_materials()
            self._bake_uv_maps()
            self.targets = [self._setup_image_target(o) for o in self.objects]
            self.target = self.targets[0]
        self._select_only(self.objects)

    def _whiten_dark_materials(self, obj):
        """Irradiance bakes divide Cycles' diffuse pass by the diffuse colour, so a black or
        fully metallic surface bakes 0 instead of its irradiance. Without bounces the surface's
        own colour plays no part in the light, so such materials are swapped for a white
        diffuse one during the bake (restored on exit); with bounces their colour matters for
        the interreflection and the bake is refused with what to change."""
        dark = [slot for slot in obj.material_slots if slot.material is not None
                and dark_material_reason(slot.material)]
        if not dark:
            return
        if self.bounces > 0:
            mat = dark[0].material
            raise BakeInputError(
                f"{obj.name}'s material {mat.name!r} is {dark_material_reason(mat)}: an "
                "irradiance bake divides by the diffuse colour and would give 0; bake with 0 "
                "bounces (the colour then plays no part) or give it a diffuse colour")
        white = bpy.data.materials.new(f"{_PREFIX}White")
        self._created.append((bpy.data.materials, white))
        bsdf = ensure_node_tree(white).nodes.get("Principled BSDF")
        bsdf.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bsdf.inputs["Metallic"].default_value = 0.0
        for slot in dark:
            old = slot.material
            slot.material = white
            self._restore.append(lambda s=slot, m=old: setattr(s, "material", m))

    def _bypass_previews(self):
        """Bake the user's shading, not our relight previews: in every material whose active
        output is a preview output, make the user's own output active for the bake."""
        for mat in bpy.data.materials:
            tree = mat.node_tree
            if tree is None:
                continue
            outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
            ours = [n for n in outputs if n.get("relight_preview") and n.is_active_output]
            theirs = [n for n in outputs if not n.get("relight_preview")]
            if ours and theirs:
                theirs[0].is_active_output = True
                self._restore.append(lambda o=ours[0]: setattr(o, "is_active_output", True))

    def _setup_vertex_target(self, obj):
        """A temporary float colour attribute per vertex, made the active colour attribute."""
        attrs = obj.data.color_attributes
        old_active = attrs.active_color_name
        old_render = attrs.render_color_index
        target = attrs.new(f"{_PREFIX}Target", "FLOAT_COLOR", self.domain)
        lit = (_corners_with_area if self.domain == "CORNER" else _vertices_with_area)(obj.data)
        self._lit_vertices = getattr(self, "_lit_vertices", []) + [lit]
        name = target.name
        attrs.active_color = target

        def restore(mesh=obj.data):
            attrs = mesh.color_attributes
            attrs.remove(attrs[name])
            if old_active and old_active in attrs:
                attrs.active_color = attrs[old_active]
            if 0 <= old_render < len(attrs):
                attrs.render_color_index = old_render

        self._restore.append(restore)
        return target

    def _unshare_materials(self):
        """Give every later object that uses an earlier object's material a temporary copy, so
        each object bakes into its own image (restored on exit)."""
        seen = set()
        for o in self.objects:
            mine = set()
            for slot in o.material_slots:
                mat = slot.material
                if mat is None:
                    continue
                if mat.name in seen:
                    copy = mat.copy()
                    self._created.append((bpy.data.materials, copy))
                    slot.material = copy
                    self._restore.append(lambda s=slot, m=mat: setattr(s, "material", m))
                    mat = copy
                mine.add(mat.name)
            seen |= mine

    def _bake_uv_maps(self):
        """Every object's bake UV map (:func:`.meshes.bake_uv_name`) made its active map for the
        bake (restored on exit), and named to Cycles (``uv_layer``) where all objects' maps
        share one name: the map Cycles bakes into is ours, not Blender's default."""
        from .meshes import bake_uv_name

        names = []
        for o in self.objects:
            name = bake_uv_name(o)
            names.append(name)
            layers = o.data.uv_layers
            if layers.active is None or layers.active.name != name:
                old = layers.active.name if layers.active is not None else None
                layers.active = layers[name]
                self._restore.append(lambda ls=layers, n=old: n is not None and setattr(
                    ls, "active", ls[n]))
        self.uv_layer = names[0] if len(set(names)) == 1 else ""
        self.uv_maps = names

    def _setup_image_target(self, obj):
        """Our own float image, made the active node of every material of ``obj``."""
        r = self.resolution
        target = self._new_image(f"{_PREFIX}Target", r, r)
        for mat in {s.material for s in obj.material_slots if s.material}:
            tree = ensure_node_tree(mat)
            node = tree.nodes.new("ShaderNodeTexImage")
            node.name = node.label = f"{_PREFIX}Target"
            node.image = target
            old_active = tree.nodes.active
            tree.nodes.active = node
            self._restore.append(lambda t=tree, n=node, a=old_active: (
                setattr(t.nodes, "active", a), t.nodes.remove(n)))
        return target

    def _bake_as_surfaces(self, objs, view_layer):
        """The baked objects as plain surfaces for the session, restored on exit: a holdout
        or shadow catcher is baked black by Cycles (measured, bpy 5.0.1: the statue's and the
        ground's DIFFUSE bakes all zero), where the other objects' bakes see it as a plain
        surface (its shadow and bounce light unchanged) -- so its flag is cleared, as the
        rays' stages see it; and a collection hidden in the viewport (its eye icon: the render
        ignores it) is shown, as Cycles' bake of an object in it is black too (docs/
        bake-files.md "The scene's visibility flags")."""
        from .visibility import _paths

        for o in objs:
            for flag in ("is_holdout", "is_shadow_catcher"):
                if getattr(o, flag, False):
                    setattr(o, flag, False)
                    self._restore.append(lambda o=o, f=flag: setattr(o, f, True))
            for path in _paths(view_layer.layer_collection, o):
                for lc in path[1:]:
                    if lc.hide_viewport:
                        lc.hide_viewport = False
                        self._restore.append(lambda lc=lc: setattr(lc, "hide_viewport", True))

    def _select_only(self, objs):
        """Select only the baked objects (bake works on the selection); restored on exit."""
        view_layer = bpy.context.view_layer
        # Not view_layer.objects: right after an object was removed (our session Sun, at the
        # teardown of an earlier bake) its list can hold a stale None or a dangling pointer
        # until the next sync -- reading it crashed Blender 5.0.1 in about 1 run in 6.
        # select_get() syncs the view layer before it looks the object up.
        selected = [o for o in bpy.data.objects if o.select_get(view_layer=view_layer)]
        active = view_layer.objects.active
        hidden = [(o.hide_get(), o.hide_viewport, o.hide_render) for o in objs]
        for o in objs:
            o.hide_set(False)
            o.hide_viewport = False
            o.hide_render = False
        self._bake_as_surfaces(objs, view_layer)

        def restore_selection():
            # only touch the objects we changed: the view layer's list can hold stale entries
            # right after a temporary object (the truth Sun) was removed
            for o in objs:
                o.select_set(o in selected)
            for o in selected:
                o.select_set(True)
            view_layer.objects.active = active
            for o, h in zip(objs, hidden):
                o.hide_set(h[0])
                o.hide_viewport, o.hide_render = h[1], h[2]

        self._restore.append(restore_selection)
        for o in selected:
            o.select_set(False)
        for o in objs:
            o.select_set(True)
        view_layer.objects.active = objs[0]

    def _new_image(self, name, width, height):
        image = bpy.data.images.new(name, width, height, float_buffer=True, alpha=False)
        image.colorspace_settings.name = "Non-Color"  # before any pixels are written
        self._created.append((bpy.data.images, image))
        return image

    # -- baking ----------------------------------------------------------------------------------
    def bake(self, environment: np.ndarray) -> np.ndarray:
        """Bake under one environment image (the first object's result; see :meth:`bake_all`).

        Parameters
        ----------
        environment : ndarray, shape (H, W) or (H, W, 3)
            Equirectangular radiance (W/sr/m^2 in Blender's units), row 0 at the bottom
            (elevation -90 degrees), Blender's longitude convention; may be negative.

        Returns
        -------
        values : ndarray, shape (R, R, 3) or (V, 3) per vertex, float32
            Baked values (textures: row 0 at v = 0).
        """
        return self.bake_all(environment)[0]

    def bake_all(self, environment: np.ndarray) -> list:
        """Bake every object under one environment image (same arguments as :meth:`bake`);
        returns one array per object, in the order given."""
        env = np.asarray(environment, dtype=np.float32)
        h, w = self.env_size
        if env.shape[:2] != (h, w) or env.ndim not in (2, 3):
            raise BakeInputError(f"environment must have shape {(h, w)} or {(h, w, 3)}, got {env.shape}")
        if not np.all(np.isfinite(env)):
            raise BakeInputError("environment has NaN or inf texels")
        set_image_pixels(self.env_image, env)
        self.env_image.update()
        start = time.perf_counter()
        with _reports_to_stderr():   # Blender's "Info: Baking map saved ..." is not a result
            result = bpy.ops.object.bake(type="DIFFUSE", use_clear=True, margin=self.margin,
                                         margin_type="EXTEND",
                                         **self._uv_kw())
        self.bake_seconds += time.perf_counter() - start
        self.bake_calls += 1
        if "FINISHED" not in result:
            raise RuntimeError(f"Cycles bake did not finish: {result}")
        if self.per_vertex:
            out = []
            for target, lit in zip(self.targets, self._lit_vertices):
                values = color_attribute(target)[:, :3].copy()
                values[~lit] = 0.0
                out.append(values)
            return out
        return [image_pixels(target)[..., :3].copy() for target in self.targets]

    def _uv_kw(self) -> dict:
        """``uv_layer=`` for bpy.ops.object.bake: the bake's map (image targets, one name)."""
        name = "" if self.per_vertex else getattr(self, "uv_layer", "")
        return {"uv_layer": name} if name else {}

    def bake_sun(self, direction, strength: float, angle_deg: float) -> np.ndarray:
        """Bake under a Cycles Sun lamp only (the environment set to black).

        Parameters
        ----------
        direction : array_like, shape (3,)
            Unit vector towards the sun, world frame (z up).
        strength : float
            Sun strength: normal irradiance in W/m^2.
        angle_deg : float
            Angular diameter of the sun disc in degrees (0 = hard shadows).

        Returns
        -------
        texture : ndarray, shape (R, R, 3), float32
        """
        return self.bake_sun_all(direction, strength, angle_deg)[0]

    def bake_sun_all(self, direction, strength: float, angle_deg: float) -> list:
        """:meth:`bake_sun` for every object: one array per object."""
        import math

        from mathutils import Vector

        # One Sun for the whole session, rotated between bakes: adding and removing an object
        # per bake made Cycles re-sync the scene (BVH included) every call -- 190 ms instead of
        # ~50 ms per 256^2 1-spp bake. Between sun bakes its strength is 0, so environment
        # bakes of the same session are unaffected.
        if getattr(self, "_sun", None) is None:
            data = bpy.data.lights.new(f"{_PREFIX}Sun", type="SUN")
            self._created.append((bpy.data.lights, data))
            data.energy = 0.0
            sun = bpy.data.objects.new(f"{_PREFIX}Sun", data)
            self._created.append((bpy.data.objects, sun))
            self.scene.collection.objects.link(sun)
            self._sun = sun
        sun = self._sun
        sun.data.energy = float(strength)
        sun.data.angle = math.radians(float(angle_deg))
        try:
            towards = Vector(np.asarray(direction, dtype=np.float64).tolist()).normalized()
            # a sun shines along its local -z: point -z away from the light direction
            sun.rotation_euler = (-towards).to_track_quat("-Z", "Y").to_euler()
            h, w = self.env_size
            return self.bake_all(np.zeros((h, w), dtype=np.float32))
        finally:
            sun.data.energy = 0.0


    def bake_shifted_normals(self, offsets):
        """Generator: for each offset ``(du, dv)`` in texels of ``offsets`` (n, 2), Cycles'
        NORMAL bake (1 spp: the texel centre) of every object at texel centres moved by that
        offset, as :meth:`bake_normals` returns it. The offsets move a temporary copy of each
        object's bake UV map (the resolution, and so Cycles' ray differentials, unchanged), which
        is removed again, the maps' active and render flags as they were
        (``lt_addon/rays/normal_samples.py`` says why). Raises RuntimeError where a mesh takes
        no UV map of ours (linked data, Blender's eight maps) or its modifiers do not carry the
        copy as they carry the bake's map (a UV Warp, a UV Project: checked on the evaluated
        mesh at the first offset)."""
        if self.per_vertex or self.samples != 1:
            raise BakeInputError("shifted normals are baked into textures at 1 spp")
        name = f"{_PREFIX}NormalShift"
        layers, base, checked = [], [], False
        try:
            for o, uv_name in zip(self.objects, self.uv_maps):
                uvs = o.data.uv_layers
                if name in uvs:
                    raise RuntimeError(f"{o.name} already has a UV map named {name}")
                active, render = uvs.active.name, [u.active_render for u in uvs]
                src = np.empty(len(o.data.loops) * 2, np.float32)
                uvs[uv_name].data.foreach_get("uv", src)
                layer = uvs.new(name=name, do_init=False)
                if layer is None:
                    raise RuntimeError(f"{o.name}: no UV map can be added (at most 8)")
                layers.append((o.data, layer.name))
                if layer.name != name:     # (an attribute of that name: the bake names ours)
                    raise RuntimeError(f"{o.name}: the UV map {name} was named {layer.name}")
                uvs.active = uvs[active]
                for u, r in zip(uvs, render + [False]):
                    u.active_render = r
                base.append(src)
            R = self.resolution
            for du, dv in np.asarray(offsets, np.float64).reshape(-1, 2):
                for (mesh, lname), src in zip(layers, base):
                    moved = src.copy()
                    moved[0::2] += np.float32(du / R)
                    moved[1::2] += np.float32(dv / R)
                    mesh.uv_layers[lname].data.foreach_set("uv", moved)
                    mesh.update()
                if not checked:
                    self._check_shifted(name, (du / R, dv / R))
                    checked = True
                yield self.bake_normals(uv_layer=name)
        finally:
            for mesh, lname in layers:
                layer = mesh.uv_layers.get(lname)
                if layer is not None:
                    mesh.uv_layers.remove(layer)
                mesh.update()

    def _check_shifted(self, name: str, shift) -> None:
        """Raise RuntimeError unless every object's evaluated mesh holds the UV map ``name``
        equal to its bake map moved by ``shift`` (u, v)."""
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for o, uv_name in zip(self.objects, self.uv_maps):
            mesh = o.evaluated_get(depsgraph).data
            got = mesh.uv_layers.get(name)
            if got is None:
                raise RuntimeError(f"{o.name}: its modifiers drop a copy of its UV map")
            a = np.empty(len(mesh.loops) * 2, np.float32)
            b = np.empty_like(a)
            got.data.foreach_get("uv", a)
            mesh.uv_layers[uv_name].data.foreach_get("uv", b)
            d = (a - b).reshape(-1, 2) - np.asarray(shift, np.float32)
            if len(d) and np.abs(d).max() > 1e-5 + 1e-6 * np.abs(b).max():
                raise RuntimeError(f"{o.name}: its modifiers change its UV map {uv_name} "
                                   "other than a copy of it (UV Warp, UV Project, a Mirror's "
                                   "UV flip)")

    def bake_normals(self, uv_layer: str | None = None) -> list:
        """Shading normals per texel of every object (Cycles' NORMAL bake, object space), as
        unit vectors (R, R, 3) float64 in the object's frame; texels no UV island covers (nor
        the margin) come back as zero vectors. Image targets only. ``uv_layer``: the UV map
        that places the texels, if not the bake's own."""
        if self.per_vertex:
            raise BakeInputError("normals are baked into textures, not per vertex")
        start = time.perf_counter()
        with _reports_to_stderr():
            result = bpy.ops.object.bake(type="NORMAL", normal_space="OBJECT", use_clear=True,
                                         margin=self.margin, margin_type="EXTEND",
                                         **({"uv_layer": uv_layer} if uv_layer else
                                            self._uv_kw()))
        self.bake_seconds += time.perf_counter() - start
        self.bake_calls += 1
        if "FINISHED" not in result:
            raise RuntimeError(f"Cycles bake did not finish: {result}")
        out = []
        for target in self.targets:
            n = image_pixels(target)[..., :3].astype(np.float64) * 2.0 - 1.0
            length = np.linalg.norm(n, axis=-1, keepdims=True)
            out.append(np.where(length > 0.5, n / np.maximum(length, 1e-12), 0.0))
        return out
