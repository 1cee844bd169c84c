"""The few bpy API differences between the supported Blender versions (4.2 LTS to 5.x), in one
place, so the rest of the code runs the same on every version without scattered version checks.

* Before Blender 5.0 a new material or world has ``node_tree is None`` until ``use_nodes`` is
  set; from 5.0 on every material/world has a node tree and ``use_nodes`` is deprecated (reading
  or writing it warns). :func:`ensure_node_tree` returns the tree on both.
* EEVEE's render engine id is ``BLENDER_EEVEE_NEXT`` in 4.2-4.5, ``BLENDER_EEVEE`` from 5.0:
  :data:`EEVEE_ENGINE`.
* Blender 5 warns about a ``DIR_PATH``/``FILE_PATH`` string property whose value starts with
  ``//`` unless the property declares ``PATH_SUPPORTS_BLEND_RELATIVE``, an option older versions
  reject. :func:`path_options` gives the options to pass.
"""

from __future__ import annotations

import bpy

#: Blender 5.0 gave every material and world a node tree and deprecated ``use_nodes``.
_ALWAYS_NODES = bpy.app.version >= (5, 0, 0)

#: ``scene.render.engine`` of EEVEE on this Blender.
EEVEE_ENGINE = "BLENDER_EEVEE" if _ALWAYS_NODES else "BLENDER_EEVEE_NEXT"

#: Whether ``StringProperty(options=...)`` knows ``PATH_SUPPORTS_BLEND_RELATIVE``.
HAS_BLEND_RELATIVE_OPTION = "is_path_supports_blend_relative" in \
    bpy.types.Property.bl_rna.properties


def ensure_node_tree(id_block):
    """The node tree of a material or world, switching its nodes on first where the Blender
    version needs it (before 5.0: ``use_nodes = True``, which also builds the default nodes)."""
    if _ALWAYS_NODES and id_block.node_tree is not None:
        return id_block.node_tree
    if id_block.node_tree is None or not id_block.use_nodes:
        id_block.use_nodes = True
    return id_block.node_tree


def path_options() -> set[str]:
    """``options`` for a path ``StringProperty`` whose value may be blend-relative (``//``)."""
    return {"ANIMATABLE", "PATH_SUPPORTS_BLEND_RELATIVE"} if HAS_BLEND_RELATIVE_OPTION \
        else {"ANIMATABLE"}
