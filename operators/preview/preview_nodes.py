"""The live preview: a "Steerable Illumination" shader node group and its material wiring (bpy).

The group recombines the basis textures for a light direction entirely inside the node tree,
so moving a slider (or the Sun lamp) needs no Python at all:

1. light direction ``d`` (normalised) -- world frame, or per pixel in the UV tangent frame
   ``(d.T, d.B, d.N)`` with ``T`` the UV tangent, ``N`` the shading normal, ``B = N x T``;
2. disk point ``(x0, y0) = (dx, dy) / sqrt(1 + dz)`` (Ashikhmin & Shirley eq. 7);
3. 1D coefficients ``c_i(x) = a_i cos(i w x + 3 (i - 1) pi / 2)``, products ``c_ij = c_i(x0) c_j(y0)``;
4. ``S = sum_ij c_ij * tile_ij`` from one padded atlas image (one GPU sampler, see
   :mod:`..lt_addon.io.atlas`), clamped at 0 (sec. 7.1);
5. calibration gain ``max(dz, 0) / max(E(w0), floor * E_zenith)`` with
   ``E(w0) = sum_ij c_ij E_ij`` (:mod:`..lt_addon.steerable.calibration`, steerable cos-law);
6. output ``S * gain * intensity * colour`` (times an albedo input in irradiance mode).

This equals :meth:`SteerableTexture.relight` up to float32 rounding and the half-float atlas
(tests render it with Cycles and compare with NumPy).

Material wiring is reversible and leaves renders alone: the nodes live in a frame "Relight
Preview" and end in a Material Output of target EEVEE, so Material Preview shows the preview
while Cycles (renders, bakes) keeps the user's own active output; :func:`remove_preview`
deletes them (and puts back a material copied because other objects share it). Scene sliders
are ID custom properties on the scene (``relight_azimuth`` ...), read by
simple single-variable drivers, so the preview also works where the extension is not installed.
"""

from __future__ import annotations

import math
import os

import bpy

from ...lt_addon.io import exrio
from ...lt_addon.io.atlas import atlas_layout, pack_atlas
from ..base.compat import ensure_node_tree

GROUP_PREFIX = "Steerable Illumination"
FRAME_NAME = "Relight Preview"
#: the bake kinds with a preview; a material holds at most one preview of each
PREVIEW_KINDS = ("steerable_texture", "transport_texture", "eigentransport", "material_tensors",
                 "sun_study")
_TAG = "relight_preview"  # custom property marking our nodes
OWNER = "relight_object"  # custom property: the object a preview's group belongs to

#: Scene slider properties: name -> (default, min, max, description)
SLIDERS = {
    "relight_azimuth": (30.0, -360.0, 360.0, "Light azimuth in degrees (from +x towards +y)"),
    "relight_elevation": (45.0, -90.0, 90.0, "Light elevation in degrees above the horizon"),
    "relight_intensity": (1.0, 0.0, 1000.0, "Light normal irradiance (like a Sun's strength)"),
    "relight_follow_sun": (0.0, 0.0, 1.0, "1: take the direction from the followed Sun lamp"),
}
COLOR_SLIDER = "relight_color"


# ---------------------------------------------------------------------------------------------
# small node helpers


class _Builder:
    """Adds nodes to a tree on a simple grid so the generated tree stays readable."""

    def __init__(self, tree):
        self.tree = tree
        self.nodes, self.links = tree.nodes, tree.links

    def node(self, kind, x, y, **attrs):
        n = self.nodes.new(kind)
        n.location = (x, y)
        for k, v in attrs.items():
            setattr(n, k, v)
        return n

    def math(self, op, a, b=None, c=None, x=0, y=0, clamp=False):
        n = self.node("ShaderNodeMath", x, y, operation=op, use_clamp=clamp)
        for i, v in enumerate((a, b, c)):
            self._feed(n.inputs[i], v)
        return n.outputs[0]

    def vmath(self, op, a, b=None, x=0, y=0, scale=None):
        n = self.node("ShaderNodeVectorMath", x, y, operation=op)
        self._feed(n.inputs[0], a)
        if b is not None:
            self._feed(n.inputs[1], b)
        if scale is not None:
            self._feed(n.inputs["Scale"], scale)
        return n.outputs["Value"] if op in ("DOT_PRODUCT", "LENGTH", "DISTANCE") else n.outputs["Vector"]

    def _feed(self, socket, value):
        if value is None:
            return
        if isinstance(value, bpy.types.NodeSocket):
            self.links.new(value, socket)
        else:
            socket.default_value = value


def _basis_constants(texture):
    basis = texture.basis
    cal = texture.calibration_model()
    return basis, cal


# ---------------------------------------------------------------------------------------------
# the node group


def after_sum(b, vector, acc, x, y):
    """``vector`` made to depend on the running (scalar) sum ``acc`` without changing it (adds
    ``acc > 1e30``, 0 for any real sum, which constant folding cannot remove). Cycles' SVM
    compiles a shader graph in waves of ready nodes, so without it every tile's lookups are
    compiled, and held on its 255-float stack, before the first sum: "out of SVM stack space"
    from about 40 tiles (measured: 32 tiles rendered, 50 did not). Chained through the sum,
    each tile's lookups wait for the previous tile and the stack holds one tile at a time."""
    if acc is None:
        return vector
    never = b.math("GREATER_THAN", acc, 1e30, x=x, y=y)
    return b.vmath("ADD", vector, never, x=x + 100, y=y)


def new_light_group(name: str):
    """A new tagged shader node group with the preview groups' light inputs -- Light Direction
    (towards the light), Intensity, Color -- so a group node can swap between such groups (sun
    and environment) and keep its links; callers add further inputs and the output."""
    group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    group[_TAG] = True
    iface = group.interface
    s = iface.new_socket("Light Direction", in_out="INPUT", socket_type="NodeSocketVector")
    s.default_value = (0.0, 0.0, 1.0)
    s = iface.new_socket("Intensity", in_out="INPUT", socket_type="NodeSocketFloat")
    s.default_value, s.min_value = 1.0, 0.0
    s = iface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor")
    s.default_value = (1.0, 1.0, 1.0, 1.0)
    return group


def build_group(texture, atlas_image, uv_map: str, name: str | None = None):
    """Create the "Steerable Illumination" node group for ``texture`` sampling ``atlas_image``.

    Inputs: Light Direction (vector, towards the light), Intensity, Color, Albedo (used in
    irradiance mode). Output: Color.
    """
    if texture.calibration != "steerable_cos":
        raise ValueError("the live preview implements the steerable_cos calibration only")
    basis, cal = _basis_constants(texture)
    n1, n = basis.order, basis.order ** 2
    group = new_light_group(name or f"{GROUP_PREFIX}")
    iface = group.interface
    s_alb = iface.new_socket("Albedo", in_out="INPUT", socket_type="NodeSocketColor")
    s_alb.default_value = (0.8, 0.8, 0.8, 1.0)
    iface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")

    b = _Builder(group)
    gin = b.node("NodeGroupInput", -2400, 0)
    gout = b.node("NodeGroupOutput", 2400, 0)
    d = b.vmath("NORMALIZE", gin.outputs["Light Direction"], x=-2200, y=0)

    if texture.frame == "tangent":
        tangent = b.node("ShaderNodeTangent", -2400, -300, direction_type="UV_MAP", uv_map=uv_map)
        geometry = b.node("ShaderNodeNewGeometry", -2400, -500)
        normal = geometry.outputs["Normal"]
        t_vec = tangent.outputs["Tangent"]
        bitangent = b.vmath("CROSS_PRODUCT", normal, t_vec, x=-2200, y=-400)
        dx = b.vmath("DOT_PRODUCT", d, t_vec, x=-2000, y=100)
        dy = b.vmath("DOT_PRODUCT", d, bitangent, x=-2000, y=0)
        dz = b.vmath("DOT_PRODUCT", d, normal, x=-2000, y=-100)
    else:
        sep = b.node("ShaderNodeSeparateXYZ", -2000, 0)
        b.links.new(d, sep.inputs[0])
        dx, dy, dz = sep.outputs["X"], sep.outputs["Y"], sep.outputs["Z"]

    # disk point (eq. 7): divide by sqrt(1 + dz), guarded at dz = -1 (the light is off there)
    root = b.math("SQRT", b.math("MAXIMUM", b.math("ADD", dz, 1.0, x=-1800, y=-100), 1e-6,
                                 x=-1700, y=-100), x=-1600, y=-100)
    x0 = b.math("DIVIDE", dx, root, x=-1500, y=100)
    y0 = b.math("DIVIDE", dy, root, x=-1500, y=0)

    # 1D steering coefficients
    def coefficients(x, y_loc):
        out = []
        for i in range(1, n1 + 1):
            phase = 3.0 * (i - 1) * math.pi / 2.0
            arg = b.math("MULTIPLY_ADD", x, i * float(basis.w), phase, x=-1300, y=y_loc - 60 * i)
            cos = b.math("COSINE", arg, x=-1150, y=y_loc - 60 * i)
            out.append(b.math("MULTIPLY", cos, float(basis.a[i - 1]), x=-1000, y=y_loc - 60 * i))
        return out

    cx = coefficients(x0, 1200)
    cy = coefficients(y0, 600)

    # UV -> tile coordinates (tileable patches wrap with fract)
    uv = b.node("ShaderNodeUVMap", -1300, -800, uv_map=uv_map).outputs["UV"]
    if texture.frame == "tangent":
        uv = b.vmath("FRACTION", uv, x=-1150, y=-800)

    lay = atlas_layout(n, texture.resolution)
    acc_color = None
    acc_e = None
    for k in range(n):
        i, j = divmod(k, n1)
        y_loc = 1400 - 120 * k
        c = b.math("MULTIPLY", cx[i], cy[j], x=-700, y=y_loc)
        su, sv, ou, ov = lay["tiles"][k]
        mapping = b.node("ShaderNodeMapping", -500, y_loc, vector_type="POINT")
        b.links.new(after_sum(b, uv, None if acc_color is None else b.vmath(
            "DOT_PRODUCT", acc_color, (1.0, 0.0, 0.0), x=-900, y=y_loc), -800, y_loc),
            mapping.inputs["Vector"])
        mapping.inputs["Location"].default_value = (ou, ov, 0.0)
        mapping.inputs["Scale"].default_value = (su, sv, 1.0)
        tex = b.node("ShaderNodeTexImage", -300, y_loc, image=atlas_image,
                     interpolation="Linear", extension="EXTEND")
        b.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        term = b.vmath("SCALE", tex.outputs["Color"], x=0, y=y_loc, scale=c)
        acc_color = term if acc_color is None else b.vmath("ADD", acc_color, term, x=200, y=y_loc)
        e_k = float(cal.E[k])
        acc_e = (b.math("MULTIPLY", c, e_k, x=0, y=y_loc - 60) if acc_e is None
                 else b.math("MULTIPLY_ADD", c, e_k, acc_e, x=200, y=y_loc - 60))

    clamped = b.vmath("MAXIMUM", acc_color, (0.0, 0.0, 0.0), x=600, y=0)
    denom = b.math("MAXIMUM", acc_e, float(cal.floor * cal.E_zenith), x=600, y=-200)
    gain = b.math("DIVIDE", b.math("MAXIMUM", dz, 0.0, x=600, y=-300), denom, x=800, y=-250)
    scale = b.math("MULTIPLY", gain, gin.outputs["Intensity"], x=1000, y=-250)
    lit = b.vmath("SCALE", clamped, x=1200, y=0, scale=scale)
    tinted = b.vmath("MULTIPLY", lit, gin.outputs["Color"], x=1400, y=0)
    if texture.settings.get("mode") == "irradiance":
        tinted = b.vmath("MULTIPLY", tinted, gin.outputs["Albedo"], x=1600, y=0)
    b.links.new(tinted, gout.inputs["Color"])
    return group


# ---------------------------------------------------------------------------------------------
# atlas image on disk


def write_atlas(texture, exr_path: str) -> tuple[str, int]:
    """Write the half-float preview atlas beside the basis EXR; returns (path, bytes)."""
    padding = "wrap" if texture.frame == "tangent" else "edge"
    atlas = pack_atlas(texture.basis_images, padding)
    path = os.path.splitext(exr_path)[0] + "_atlas.exr"
    nbytes = exrio.write_exr(path, {c: atlas[..., i] for i, c in enumerate("RGB")},
                             {"format": "relightable_textures.atlas", "tiles": len(texture.basis_images),
                              "resolution": texture.resolution, "padding": padding},
                             pixel_type="half")
    return path, nbytes


def load_atlas_image(path: str, name: str):
    """Load (or reload) the atlas as a non-colour float image with a relative path if possible."""
    image = bpy.data.images.get(name)
    if image is not None and bpy.path.abspath(image.filepath) == os.path.abspath(path):
        image.reload()
    else:
        image = bpy.data.images.load(path, check_existing=False)
        image.name = name
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "NONE"
    if bpy.data.filepath:
        try:
            image.filepath = bpy.path.relpath(path)
        except ValueError:
            pass
    image[_TAG] = True
    return image


# ---------------------------------------------------------------------------------------------
# scene sliders and drivers


def ensure_sliders(scene) -> None:
    """Create the scene slider custom properties (with UI ranges) if missing."""
    for key, (default, lo, hi, desc) in SLIDERS.items():
        if key not in scene:
            scene[key] = default
        ui = scene.id_properties_ui(key)
        ui.update(min=lo, max=hi, soft_min=max(lo, -180.0) if "azimuth" in key else lo,
                  soft_max=hi, description=desc, default=default)
    if COLOR_SLIDER not in scene:
        scene[COLOR_SLIDER] = (1.0, 1.0, 1.0)
    scene.id_properties_ui(COLOR_SLIDER).update(subtype="COLOR", min=0.0, soft_max=1.0,
                                                description="Light colour (linear RGB)")


def _drive(socket_owner, path: str, index: int, id_type: str, id_block, data_path: str,
           expression: str = "var"):
    fcurve = socket_owner.driver_add(path, index) if index >= 0 else socket_owner.driver_add(path)
    drv = fcurve.driver
    drv.type = "SCRIPTED"
    while drv.variables:
        drv.variables.remove(drv.variables[0])
    var = drv.variables.new()
    var.name = "var"
    var.type = "SINGLE_PROP"
    var.targets[0].id_type = id_type
    var.targets[0].id = id_block
    var.targets[0].data_path = data_path
    drv.expression = expression  # a "simple expression": no Python needed
    return fcurve


def _controls(b, scene, sun, x, y):
    """Nodes turning the scene sliders (and the Sun) into the group's direction/intensity/colour."""
    az = b.node("ShaderNodeValue", x, y, label="Azimuth (deg)")
    el = b.node("ShaderNodeValue", x, y - 100, label="Elevation (deg)")
    inten = b.node("ShaderNodeValue", x, y - 200, label="Intensity")
    follow = b.node("ShaderNodeValue", x, y - 300, label="Follow Sun")
    color = b.node("ShaderNodeRGB", x, y - 400, label="Light Color")
    sun_dir = b.node("ShaderNodeCombineXYZ", x, y - 600, label="Sun Direction")
    for node, key in ((az, "relight_azimuth"), (el, "relight_elevation"),
                      (inten, "relight_intensity"), (follow, "relight_follow_sun")):
        node.outputs[0].default_value = float(scene[key])
        _drive(node.outputs[0], "default_value", -1, "SCENE", scene, f'["{key}"]')
    for i in range(3):
        color.outputs[0].default_value[i] = float(scene[COLOR_SLIDER][i])
        _drive(color.outputs[0], "default_value", i, "SCENE", scene, f'["{COLOR_SLIDER}"][{i}]')
    set_sun_drivers(sun_dir, sun)
    # direction from azimuth / elevation (degrees)
    az_r = b.math("RADIANS", az.outputs[0], x=x + 200, y=y)
    el_r = b.math("RADIANS", el.outputs[0], x=x + 200, y=y - 100)
    cos_el = b.math("COSINE", el_r, x=x + 350, y=y - 100)
    dir_x = b.math("MULTIPLY", cos_el, b.math("COSINE", az_r, x=x + 350, y=y), x=x + 500, y=y)
    dir_y = b.math("MULTIPLY", cos_el, b.math("SINE", az_r, x=x + 350, y=y + 100), x=x + 500, y=y - 50)
    dir_z = b.math("SINE", el_r, x=x + 500, y=y - 100)
    slider_dir = b.node("ShaderNodeCombineXYZ", x + 650, y)
    for i, s in enumerate((dir_x, dir_y, dir_z)):
        b.links.new(s, slider_dir.inputs[i])
    mix = b.node("ShaderNodeMix", x + 850, y - 200, data_type="VECTOR", clamp_factor=True)
    b.links.new(follow.outputs[0], mix.inputs["Factor"])
    b.links.new(slider_dir.outputs[0], mix.inputs[4])  # A (vector)
    b.links.new(sun_dir.outputs[0], mix.inputs[5])  # B (vector)
    return mix.outputs[1], inten.outputs[0], color.outputs[0], sun_dir


def set_sun_drivers(sun_dir_node, sun) -> None:
    """Drive the Sun Direction node from ``sun``'s local +z axis (the direction towards it)."""
    for i in range(3):
        sun_dir_node.inputs[i].driver_remove("default_value")
        if sun is not None:
            # RNA stores matrices column-major: matrix_world[2][i] is mathutils' m[i][2],
            # component i of the local +z axis
            _drive(sun_dir_node.inputs[i], "default_value", -1, "OBJECT", sun,
                   f"matrix_world[2][{i}]")
        else:
            sun_dir_node.inputs[i].default_value = (0.0, 0.0, 1.0)[i]


# ---------------------------------------------------------------------------------------------
# material wiring
#
# The preview never takes the render over (issue 57). Each bake kind's nodes end in a tagged
# Emission; at most one preview Material Output per material shows one of them, with target
# EEVEE. Blender picks the output of an engine by exact target first (``ntreeShaderOutputNode``:
# an output of target EEVEE beats one of target All whatever is active), so EEVEE -- Material
# Preview, and EEVEE's Rendered view and renders -- shows the preview, while Cycles (its renders,
# its Rendered view and its bakes) still finds the user's own output, which stays the active one.
# *Show Preview* off takes the preview output away (the user's material everywhere); Remove
# Preview takes every node of ours away and puts back a material that was copied.


#: custom property naming the bake kind a preview node belongs to (its frame, nodes and output)
_KIND = "relight_preview_kind"
#: marks our one preview Material Output of a material (older versions had one per kind)
_OUTPUT = "relight_preview_output"
#: on a kind's Emission: the kind the material shows (kept while Show Preview is off)
_SHOWN = "relight_preview_shown"
#: on our output: the name of the user's output that was active before ours had to be
_WAS_ACTIVE = "relight_preview_was_active"
#: on a material copied for one object's preview: the material it copies (an ID pointer)
COPY_OF = "relight_preview_copy_of"
#: on a material the preview made for an object that had none
MADE = "relight_preview_made"
#: on a gated preview's Mix Shader: the node our output shows (instead of the Emission)
_END = "relight_preview_end"
#: object custom property a gated preview reads (Attribute node, type Object): 1 on the objects
#: the bake covered; on others, which lack it, the attribute reads 0 and the material's own
#: surface shows
RECEIVER = "relight_preview_receiver"
#: the target of the preview's Material Output: EEVEE only, never Cycles
PREVIEW_TARGET = "EEVEE"
#: kinds whose material is copied when other objects use it too (the material edits' preview
#: reads a per-object attribute in the materials its regions are named after: never copied;
#: it is gated instead, so objects the bake did not cover show their own surface)
_COPIED_KINDS = ("steerable_texture", "transport_texture", "eigentransport", "sun_study")


def _preview_nodes(tree, kind: str | None = None):
    """Our nodes in ``tree`` (of one bake ``kind``, or all)."""
    if tree is None:
        return []
    return [n for n in tree.nodes if n.get(_TAG) and (kind is None or n.get(_KIND) == kind)]


def _emission(tree, kind: str):
    """The Emission that ends ``kind``'s preview nodes in ``tree``, or None."""
    return next((n for n in _preview_nodes(tree, kind) if n.bl_idname == "ShaderNodeEmission"),
                None)


def _outputs(tree):
    return [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]


def _our_output(tree):
    return next((n for n in _outputs(tree) if n.get(_TAG) and n.get(_OUTPUT)), None)


def _drop_output(tree, node) -> None:
    """Remove our preview output ``node``; the user's output it deactivated is active again."""
    was = node.get(_WAS_ACTIVE)
    tree.nodes.remove(node)
    theirs = [n for n in _outputs(tree) if not n.get(_TAG)]
    back = next((n for n in theirs if n.name == was), None)
    if back is not None:
        back.is_active_output = True
    elif theirs and not any(n.is_active_output for n in theirs):
        theirs[0].is_active_output = True


def _legacy_outputs(tree) -> str | None:
    """Outputs of versions before issue 57 (one per kind, target All, the shown one active, so
    renders showed the preview): removed, the user's output active again. Returns the kind the
    material showed, or None."""
    shown = None
    for node in [n for n in _outputs(tree) if n.get(_TAG) and not n.get(_OUTPUT)]:
        if node.is_active_output:
            shown = node.get(_KIND)
        _drop_output(tree, node)
    return shown


def _show_kind(tree, kind: str) -> bool:
    """Make our preview output (target EEVEE) show ``kind``'s Emission in ``tree``; False when
    the tree has no preview of that kind."""
    emission = _emission(tree, kind)
    if emission is None:
        return False
    for node in _preview_nodes(tree):
        if node.bl_idname == "ShaderNodeEmission":
            node[_SHOWN] = node == emission
    out = _our_output(tree)
    if out is None:
        out = tree.nodes.new("ShaderNodeOutputMaterial")
        out.label, out[_TAG], out[_OUTPUT] = "Relight Preview Output (EEVEE)", True, True
        out.location = (emission.location.x + 250, emission.location.y)
    out.target = PREVIEW_TARGET
    out[_KIND] = kind
    if emission.parent is not None:
        out.parent = emission.parent
    # a gated preview ends in a Mix Shader (the user's surface where the gate is 0)
    end = next((n for n in _preview_nodes(tree, kind) if n.get(_END)), emission)
    tree.links.new(end.outputs[0], out.inputs["Surface"])
    # an output of the user's with the same target would win while active: ours is made the
    # active one then (and gives it back when it goes)
    theirs = [n for n in _outputs(tree) if not n.get(_TAG)]
    if any(n.target == PREVIEW_TARGET for n in theirs):
        active = next((n for n in theirs if n.is_active_output), None)
        if active is not None:
            out[_WAS_ACTIVE] = active.name
        out.is_active_output = True
    return True


def _materials(obj) -> list:
    return list({s.material for s in obj.material_slots if s.material})


def preview_kinds(obj) -> list:
    """The bake kinds whose previews the object's materials hold, the shown one first (the
    one Show Preview shows, also while it is off)."""
    kinds, shown = set(), None
    for mat in _materials(obj):
        tree = mat.node_tree
        for n in _preview_nodes(tree):
            if n.bl_idname == "ShaderNodeEmission" and n.get(_KIND):
                kinds.add(n[_KIND])
                if n.get(_SHOWN):
                    shown = n[_KIND]
        legacy = [n for n in _outputs(tree) if n.get(_TAG) and not n.get(_OUTPUT)
                  and n.is_active_output] if tree is not None else []
        if legacy:
            shown = legacy[0].get(_KIND)
    kinds = sorted(kinds)
    return ([shown] if shown in kinds else []) + [k for k in kinds if k != shown]


def preview_shown(obj) -> bool:
    """Whether EEVEE shows a preview on ``obj`` now (a preview output in its materials)."""
    return any(mat.node_tree is not None and _our_output(mat.node_tree) is not None
               for mat in _materials(obj))


def activate_preview(obj, kind: str) -> bool:
    """Show the object's existing preview of ``kind`` (previews of different bakes coexist in
    a material; this points the preview output at its nodes). False when a material of the
    object holds no preview of that kind (nothing changed then)."""
    mats = _materials(obj)
    if not mats or any(_emission(m.node_tree, kind) is None for m in mats):
        return False
    for mat in mats:
        _legacy_outputs(mat.node_tree)
        _show_kind(mat.node_tree, kind)
    return True


def set_previews_shown(objects, shown: bool) -> int:
    """*Show Preview*: with ``shown`` False take the preview outputs of ``objects``' materials
    away (EEVEE then shows the user's material as well), with True put them back for the kind
    each material showed. Returns how many materials changed."""
    changed = 0
    for mat in {m for o in objects if o.type == "MESH" for m in _materials(o)}:
        tree = mat.node_tree
        if not _preview_nodes(tree):
            continue
        legacy = _legacy_outputs(tree)
        out = _our_output(tree)
        if not shown:
            if out is not None:
                _drop_output(tree, out)
                changed += 1
            continue
        kinds = [n.get(_KIND) for n in _preview_nodes(tree)
                 if n.bl_idname == "ShaderNodeEmission"]
        kind = legacy or next((n.get(_KIND) for n in _preview_nodes(tree)
                               if n.bl_idname == "ShaderNodeEmission" and n.get(_SHOWN)),
                              kinds[0] if kinds else None)
        if out is None and kind is not None and _show_kind(tree, kind):
            changed += 1
    return changed


#: on our output: an EEVEE render asked to show the preview (Relight Compare, the tests'
#: renders); the F12 guard leaves such a material's preview in place
RENDER_SHOWS = "relight_preview_render"


def any_preview() -> bool:
    """Whether any material holds preview nodes."""
    return any(_preview_nodes(m.node_tree) for m in bpy.data.materials
               if m.node_tree is not None)


def step_aside_for_render() -> list:
    """Take every material's preview output away for an EEVEE render (F12 keeps the user's
    materials, issue 57); returns ``(material, kind)`` pairs for :func:`step_back`. Materials
    whose preview a render asked for (:func:`render_previews`) keep it."""
    gone = []
    for mat in bpy.data.materials:
        tree = mat.node_tree
        out = _our_output(tree) if tree is not None else None
        if out is None or out.get(RENDER_SHOWS):
            continue
        gone.append((mat, out.get(_KIND)))
        _drop_output(tree, out)
    return gone


def step_back(gone) -> int:
    """Put back the preview outputs :func:`step_aside_for_render` took away (those whose
    material still exists and holds that kind's nodes). Returns how many came back."""
    back = 0
    for mat, kind in gone:
        try:
            tree = mat.node_tree
        except ReferenceError:       # the material was removed meanwhile
            continue
        if tree is not None and kind and _our_output(tree) is None and _show_kind(tree, kind):
            back += 1
    return back


def render_previews(objects, engine: str = "CYCLES") -> list:
    """Let ``engine``'s renders show the texture previews of ``objects`` (Relight Compare and
    the tests render the preview with Cycles): each such material's preview output gets that
    engine's target. Returns the callables that undo it, last first."""
    target = {"CYCLES": "CYCLES"}.get(engine, PREVIEW_TARGET)
    undo = []
    for mat in {m for o in objects for m in _materials(o)}:
        tree = mat.node_tree
        kinds = [k for k in preview_kinds_of(tree) if k != "eigentransport"]
        if not kinds:
            continue
        flags = {n.name: n.get(_SHOWN) for n in _preview_nodes(tree)
                 if n.bl_idname == "ShaderNodeEmission"}
        undo.append(lambda t=tree, f=flags: [t.nodes[k].__setitem__(_SHOWN, v)
                                             for k, v in f.items() if v is not None])
        out = _our_output(tree)
        if out is None:
            _show_kind(tree, kinds[0])
            out = _our_output(tree)
            undo.append(lambda t=tree, o=out: _drop_output(t, o))
        elif out.get(_KIND) == "eigentransport":   # a texture preview, lit like the truth
            was = out.get(_KIND)
            _show_kind(tree, kinds[0])
            undo.append(lambda t=tree, k=was: _show_kind(t, k))
        old = out.target
        out.target = target
        out[RENDER_SHOWS] = True
        undo.append(lambda o=out, t=old: (setattr(o, "target", t), o.pop(RENDER_SHOWS, None)))
    return undo[::-1]


def preview_kinds_of(tree) -> list:
    """The kinds of the previews ``tree`` holds, the shown one first."""
    emissions = [n for n in _preview_nodes(tree) if n.bl_idname == "ShaderNodeEmission"]
    emissions.sort(key=lambda n: not n.get(_SHOWN))
    return [n.get(_KIND) for n in emissions]


def _others_use(mat, obj) -> list:
    """Objects other than ``obj`` (and those sharing its mesh) whose slots hold ``mat``."""
    return sorted(o.name for o in bpy.data.objects
                  if o != obj and o.data != obj.data
                  and any(s.material == mat for s in getattr(o, "material_slots", ())))


def _own_materials(obj, kind: str) -> list:
    """Give ``obj`` its own copy of each material other objects use too, so its preview (of
    its own UVs and texture) does not show on them; returns notes, one per copy. A copy made
    for an earlier preview of ``obj`` is kept."""
    notes = []
    if kind not in _COPIED_KINDS:
        return notes
    for mat in _materials(obj):
        if mat.get(COPY_OF) is not None:
            continue
        others = _others_use(mat, obj)
        if not others:
            continue
        copy = mat.copy()
        copy.name = f"{mat.name} (Relight {obj.name})"
        copy[COPY_OF] = mat
        for slot in obj.material_slots:
            if slot.material == mat:
                slot.material = copy
        notes.append(f"{obj.name}: material {mat.name!r} is also used by "
                     f"{', '.join(others[:3])}{' ...' if len(others) > 3 else ''}; the preview "
                     f"is on a copy, {copy.name!r} (Remove Preview puts {mat.name!r} back)")
    return notes


def _restore_materials(obj) -> int:
    """Put back the materials the preview copied or made for ``obj`` once no preview is in
    them any more; returns how many slots changed."""
    changed = 0
    for slot in obj.material_slots:
        mat = slot.material
        if mat is None or _preview_nodes(mat.node_tree):
            continue
        if mat.get(COPY_OF) is not None:
            slot.material = mat[COPY_OF]
        elif mat.get(MADE):
            slot.material = None
        else:
            continue
        changed += 1
        if mat.users == 0:
            bpy.data.materials.remove(mat)
    made = obj.get(MADE)   # the slot the preview added to an object without one
    if made is not None and all(s.material is None for s in obj.material_slots):
        while len(obj.data.materials) > int(made):
            obj.data.materials.pop()
        del obj[MADE]
    return changed


def remove_preview(obj, scene=None, purge: bool = True, kind: str | None = None) -> int:
    """Remove our preview from the object's materials completely: the tagged nodes and the
    drivers on them, a material copied or made for it (the original is put back), then our
    node groups and atlas images nothing uses any more, and -- given ``scene`` and when no
    material shows a preview any more -- the scene's light sliders (so the Preview Light panel
    offers no sliders that drive nothing). Returns how many materials changed. The user's own
    nodes, their active output, images and properties are never touched. ``purge=False``
    keeps the unused groups and images (a new preview about to use them is being wired)."""
    changed = 0
    for mat in _materials(obj):
        tree = mat.node_tree
        ours = _preview_nodes(tree, kind)
        if not ours:
            continue
        legacy = _legacy_outputs(tree)
        shown = _our_output(tree)
        if shown is not None and (kind is None or shown.get(_KIND) == kind):
            _drop_output(tree, shown)
        ours = _preview_nodes(tree, kind)
        names = {f'nodes["{n.name}"]' for n in ours}
        anim = tree.animation_data
        if anim is not None:
            for fc in [fc for fc in anim.drivers if fc.data_path.split(".")[0] in names]:
                anim.drivers.remove(fc)
            if not anim.drivers and anim.action is None and not anim.nla_tracks:
                tree.animation_data_clear()
        for node in ours:
            tree.nodes.remove(node)
        if legacy and legacy != kind and kind is not None:
            _show_kind(tree, legacy)    # an older file's other kind stays shown
        changed += 1
    if purge:
        _restore_materials(obj)
    if not purge:
        return changed
    # the gate's marks on objects none of whose materials holds a gated preview any more
    for other in [o for o in bpy.data.objects if RECEIVER in o]:
        if not any(n.get(_END) for m in _materials(other) for n in _preview_nodes(m.node_tree)):
            del other[RECEIVER]
    # A group only a fake user holds is the other light mode of a transport preview: unused
    # once no group of the same object is in a material any more.
    ours = [g for g in bpy.data.node_groups if g.get(_TAG)]
    shown = {g.get(OWNER) for g in ours if g.users > int(g.use_fake_user)}
    for group in [g for g in ours if g.users == 0
                  or (g.use_fake_user and g.users == 1 and g.get(OWNER) not in shown)]:
        bpy.data.node_groups.remove(group)
    for image in [i for i in bpy.data.images if i.get(_TAG) and i.users == 0]:
        bpy.data.images.remove(image)
    if scene is not None and not any_preview():
        for key in (*SLIDERS, COLOR_SLIDER, "relight_sun"):
            if key in scene:
                del scene[key]
    return changed


def copy_notes(obj) -> list:
    """One line per material of ``obj`` that its preview shows on a copy (other objects use the
    original), for the bake's summary."""
    out = []
    for mat in _materials(obj):
        orig = mat.get(COPY_OF)
        if orig is not None:
            others = _others_use(orig, obj)
            out.append(f"{obj.name}'s preview is on a copy of material {orig.name!r}, "
                       f"{mat.name!r}: " + (f"{', '.join(others[:3])} use"
                                            f"{'s' if len(others) == 1 else ''} it too"
                                            if others else "it was shared")
                       + " (Remove Preview puts it back)")
    return out


def _user_surface(tree):
    """The socket feeding the Surface of the user's output EEVEE would show without the
    preview (exact target EEVEE first, then All; the active one first), or None."""
    theirs = [n for n in _outputs(tree) if not n.get(_TAG) and n.target in ("EEVEE", "ALL")]
    theirs.sort(key=lambda n: (n.target != "EEVEE", not n.is_active_output))
    for node in theirs:
        links = node.inputs["Surface"].links
        return links[0].from_socket if links else None
    return None


def _gate(b, emission) -> None:
    """Show the preview only on objects with :data:`RECEIVER` (a material shared with objects
    the bake did not cover shows its own surface on those): Mix Shader(attribute, user's
    surface, preview), marked as the end our output shows."""
    attr = b.node("ShaderNodeAttribute", 1100, 950, attribute_type="OBJECT",
                  attribute_name=RECEIVER, label="Baked object?")
    mix = b.node("ShaderNodeMixShader", 1300, 750, label="Preview on baked objects only")
    b.links.new(attr.outputs["Fac"], mix.inputs[0])
    surface = _user_surface(b.tree)
    if surface is not None:
        b.links.new(surface, mix.inputs[1])
    b.links.new(emission.outputs[0], mix.inputs[2])
    mix[_END] = True


def _wire_preview(obj, build_color, kind: str, gated: bool = False) -> list:
    """Put a preview of bake ``kind`` into every material of ``obj``: ``build_color(builder)``
    adds the nodes computing the preview colour and returns its socket; it ends in an Emission
    that our preview output (target EEVEE: never Cycles, never the user's active output)
    shows. A material other objects use too is copied for ``obj`` first (a note per copy is
    returned; :func:`copy_notes` says them later); an object without a material gets one (Remove
    Preview takes it away again). All new nodes are tagged with the kind and framed, so
    :func:`remove_preview` can take them out again and previews of other kinds stay (switched
    by :func:`activate_preview`); the user's nodes are not touched."""
    remove_preview(obj, purge=False, kind=kind)
    if not obj.material_slots or not any(s.material for s in obj.material_slots):
        made = bpy.data.materials.new(f"{obj.name} Relight")
        made[MADE] = True
        if not obj.material_slots:
            obj[MADE] = len(obj.data.materials)
            obj.data.materials.append(made)
        else:
            obj.material_slots[0].material = made
    notes = _own_materials(obj, kind)
    for mat in _materials(obj):
        tree = ensure_node_tree(mat)
        _legacy_outputs(tree)
        before = {nd.name for nd in tree.nodes}
        b = _Builder(tree)
        frame = b.node("NodeFrame", -200, 900, label=f"{FRAME_NAME}: {kind.replace('_', ' ')}")
        color = build_color(b)
        emission = b.node("ShaderNodeEmission", 1100, 700)
        emission.inputs["Strength"].default_value = 1.0
        b.links.new(color, emission.inputs["Color"])
        if gated:
            _gate(b, emission)
        for nd in tree.nodes:
            if nd.name not in before:
                nd[_TAG] = True
                nd[_KIND] = kind
                if nd != frame:
                    nd.parent = frame
        _show_kind(tree, kind)
        # each kind's frame in its own band of the node editor, so coexisting previews
        # do not overlap
        frame.location.y -= 1600 * PREVIEW_KINDS.index(kind)
    return notes


def install_preview(scene, obj, exr_path: str, texture, sun=None) -> dict:
    """Write the atlas, build the group and wire it into every material of ``obj``.

    Replaces an earlier preview of the same object. Returns {"atlas": path, "atlas_bytes": n,
    "group": name, "group_nodes": count}.
    """
    atlas_path, atlas_bytes = write_atlas(texture, exr_path)
    image = load_atlas_image(atlas_path, f"{obj.name} steerable atlas")
    from ..base.meshes import baked_uv_name

    uv_map = baked_uv_name(obj)
    old = bpy.data.node_groups.get(f"{GROUP_PREFIX} ({obj.name})")
    group = build_group(texture, image, uv_map, name=f"{GROUP_PREFIX} ({obj.name})")
    if old is not None:
        bpy.data.node_groups.remove(old)
        group.name = f"{GROUP_PREFIX} ({obj.name})"
    ensure_sliders(scene)
    if sun is None:
        sun = scene.get("relight_sun")

    def steered_color(b):
        direction, intensity, color, _ = _controls(b, scene, sun, -200, 800)
        gnode = b.node("ShaderNodeGroup", 900, 700, node_tree=group,
                       label="Steerable Illumination")
        b.links.new(direction, gnode.inputs["Light Direction"])
        b.links.new(intensity, gnode.inputs["Intensity"])
        b.links.new(color, gnode.inputs["Color"])
        return gnode.outputs["Color"]

    notes = _wire_preview(obj, steered_color, "steerable_texture")
    return {"atlas": atlas_path, "atlas_bytes": atlas_bytes, "group": group.name,
            "group_nodes": len(group.nodes), "copied_materials": notes}


def set_follow_sun(scene, sun) -> int:
    """Point every preview's Sun Direction drivers at ``sun`` (None: detach); returns count."""
    changed = 0
    for mat in bpy.data.materials:
        if mat.node_tree is None:
            continue
        for node in mat.node_tree.nodes:
            if node.get(_TAG) and node.bl_idname == "ShaderNodeCombineXYZ" and \
                    node.label == "Sun Direction":
                set_sun_drivers(node, sun)
                changed += 1
    if sun is not None:
        scene["relight_sun"] = sun
    elif "relight_sun" in scene:
        del scene["relight_sun"]
    return changed


def _base_color(b):
    """The material's own diffuse colour as a socket of ``b.tree``: whatever feeds the first
    Principled / Diffuse BSDF's Base Color (a texture keeps working), or its constant colour;
    None for a material without one."""
    for node in b.tree.nodes:
        if node.get(_TAG):
            continue
        name = {"ShaderNodeBsdfPrincipled": "Base Color",
                "ShaderNodeBsdfDiffuse": "Color"}.get(node.bl_idname)
        if name is None:
            continue
        socket = node.inputs[name]
        if socket.is_linked:
            return socket.links[0].from_socket
        rgb = b.node("ShaderNodeRGB", 900, 1100, label="Base Color")
        rgb.outputs[0].default_value = tuple(socket.default_value)
        return rgb.outputs[0]
    return None


def install_attribute_preview(obj, attribute: str, kind: str = "eigentransport",
                              base_color: bool = True, gated: bool = False) -> list:
    """Show a colour attribute as emission: white-surface radiance (the per-vertex
    eigentransport preview) multiplied by the material's own base colour (issue 12: an orange
    object previewed grey), or with ``base_color=False`` the attribute as it is (the material
    edits' preview, which holds the edited colours already). ``gated``: the materials are not
    copied (the material edits' are the ones the user edits), so the preview shows only on
    objects marked :data:`RECEIVER` (set here on ``obj``); other objects sharing a material
    keep its own surface."""
    if gated:
        obj[RECEIVER] = 1.0
    def build(b):
        light = b.node("ShaderNodeVertexColor", 900, 900, layer_name=attribute).outputs["Color"]
        base = _base_color(b) if base_color else None
        if base is None:
            return light
        mul = b.node("ShaderNodeVectorMath", 1000, 1000, operation="MULTIPLY",
                     label="Light x Base Color")
        b.links.new(light, mul.inputs[0])
        b.links.new(base, mul.inputs[1])
        return mul.outputs[0]

    return _wire_preview(obj, build, kind, gated=gated)
