"""The "Relight" tab in the 3D viewport sidebar (bpy)."""

from __future__ import annotations

import bpy

from .blend_files import object_bakes


class VIEW3D_PT_relight(bpy.types.Panel):
    """Relightable data of the active object"""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Relight"
    bl_label = "Relightable Textures"

    def draw(self, context):
        layout = self.layout
        obj = context.active_object
        if obj is None:
            layout.label(text="Select a mesh object to relight", icon="INFO")
            return
        if obj.type != "MESH":
            layout.label(text=f"{obj.name} is a {obj.type.lower()}, not a mesh", icon="ERROR")
            layout.label(text="Relighting works on mesh objects only")
            return
        box = layout.box()
        box.label(text=obj.name, icon="MESH_DATA")
        mesh = obj.data
        box.label(text=f"{len(mesh.vertices)} vertices, {len(mesh.polygons)} faces")
        if not mesh.uv_layers:
            box.label(text="No UV map: texture bakes need one", icon="ERROR")
        bakes = object_bakes(obj)
        if not bakes:
            box.label(text="No relightable data yet")
        for bake in bakes:
            box.label(text=f"{bake.get('kind', '?')}: {bake.get('path', '?')}", icon="IMAGE_DATA")


class VIEW3D_PT_relight_samples(bpy.types.Panel):
    """Add the paper sample scenes"""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Relight"
    bl_label = "Sample Scenes"
    bl_parent_id = "VIEW3D_PT_relight"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = context.scene.relight
        col = self.layout.column()
        col.prop(settings, "sample_name")
        col.prop(settings, "sample_size")
        op = col.operator("relight.add_sample_scene", icon="ADD")
        op.name = settings.sample_name
        op.size = settings.sample_size


CLASSES = (VIEW3D_PT_relight, VIEW3D_PT_relight_samples)
