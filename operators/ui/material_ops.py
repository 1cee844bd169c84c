"""The panel's *Bake Materials* operator and the material property it adds (bpy); the bake
job, the live preview and its depsgraph handler are :mod:`..bakes.material_edit`."""

from __future__ import annotations

import re

import bpy

from ..bakes import material_bake
from ..bakes.material_edit import SUMMARY_KEY, bake_job, on_depsgraph_update
from ..base.cycles_bake import BakeInputError
from ...lt_addon.settings import to_argv
from .bake_ops import ModalBake, transport_objects
from .properties import MATERIAL_FIELDS, MATERIAL_PROPS
from .settings_props import values


class RELIGHT_OT_bake_materials(ModalBake, bpy.types.Operator):
    """Bake transfer tensors of the selected meshes (Sun 2007) so the materials marked Editable
    can be recoloured with their interreflection following live (Esc cancels)"""

    bl_idname = "relight.bake_materials"
    bl_label = "Bake Materials"
    bl_options = {"REGISTER", "UNDO"}   # one undo step, as the texture bake

    def _prepare(self, context):
        scene, props = context.scene, context.scene.relight
        objects = transport_objects(context)
        regions = [m.name for m in material_bake.scene_materials(scene)
                   if m is not None and m.relight_editable]
        if not regions:
            raise BakeInputError("mark at least one material Editable in the Material Edits "
                                 "panel")
        rough = ",".join(v for v in re.split(r"[,\s]+", props.material_anchors) if v)
        settings = material_bake.MaterialBakeSettings(
            regions=regions, anchors=f"roughness:{rough}" if rough else "diffuse",
            anchor_directions=f"hemi:{props.material_anchor_directions}",
            domain="CORNER" if props.material_per_corner else "POINT",
            directions=(f"hemi:{props.material_directions}:1.5",
                        f"hemi:{props.material_one_directions}",
                        f"hemi:{props.material_two_directions}"),
            **values(material_bake.MaterialBakeSettings, props, MATERIAL_FIELDS,
                     rename=MATERIAL_PROPS))
        settings.validate()
        if props.run_on != "HERE":
            d0, d1, d2 = settings.specs()
            args = [a for o in objects for a in ("--object", o.name)]
            args += [a for r in regions for a in ("--region", r)]
            return self._external(context, "bake-materials", args + to_argv(settings) + [
                "--directions", d0, "--one-bounce-directions", d1, "--two-bounce-directions",
                d2] + (["--per-corner"] if settings.domain == "CORNER" else []))
        stage = self._make_out_dir(props)
        return bake_job(scene, objects, settings, stage)

    def _cancel_note(self, context) -> str:
        return "; its finished chunks are kept, so baking again resumes"

    def _finish(self, context, result):
        rep = result.report
        s = rep["energy_shares"]
        g = rep.get("gather")
        rays = f" + {g['rays_per_origin']} rays a receiver" if g else ""
        text = (f"Baked {len(rep['objects'])} objects, {rep['vertices']} vertices: "
                f"{rep['bake_calls']} Cycles bakes{rays} in "
                f"{rep['timings']['wall_total']:.1f} s, "
                f"{rep['bytes']['tensors'] / 2**20:.1f} MiB; light direct {s['direct']:.2f}, "
                f"1 bounce {s['one_bounce']:.2f}, 2 bounces {s['two_bounce']:.2f}")
        context.scene[SUMMARY_KEY] = text
        from .bake_ops import after_preview, remember_bake, report_warnings

        report_warnings(self, rep.get("warnings", rep["notes"]))   # notes and checks
        self.report({"INFO"}, text)
        remember_bake(self.out_dir)
        after_preview(self, context)


CLASSES = (RELIGHT_OT_bake_materials,)


def register() -> None:
    bpy.types.Material.relight_editable = bpy.props.BoolProperty(
        name="Editable", default=False,
        description="Bake Materials keeps this material's colour editable, with the light it "
                    "throws on the rest of the scene following (Sun 2007)")
    bpy.app.handlers.depsgraph_update_post.append(on_depsgraph_update)


def unregister() -> None:
    if on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(on_depsgraph_update)
    del bpy.types.Material.relight_editable

