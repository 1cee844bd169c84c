"""Bake per-vertex transfer tensors for material edits with Cycles (bpy), Sun et al. 2007.

Each term of :mod:`..lt_addon.transport.ptt` is an ordinary Cycles per-vertex DIFFUSE bake
(irradiance mode: no colour pass, so ``E / pi``) under one hard Sun lamp, with every material
in the scene temporarily replaced by a *gated* Diffuse BSDF whose colour depends on the
Light Path node's Ray Depth:

* depth 0 (the bake's receiver, a camera ray to Cycles): white, so the bake is irradiance;
* depth 1 (the surface the light reflects off last): the material's colour times ``g1``;
* depth 2 (the surface before it): the colour times ``g2``; deeper: black.

Editable regions take colour 1 (white) and fixed materials their own colour. With Cycles'
bounces capped at 2 and the indirect pass only:

* one bounce off region ``r``: ``g1 = [region == r]``, ``g2 = 0``;
* two bounces ``r1 -> r2``: ``g1 = [region == r2]``, ``g2 = [region == r1]``, minus the same
  bake with ``g2 = 0`` (the one-bounce light of ``r2``). Both use the same seed, so every path
  makes the same random choices up to the second surface and the difference is exactly the
  light that took the second bounce (it is >= 0; measured: the two bakes of a floor's one-bounce
  light off a wall were equal to the last bit).

Every light direction bakes with its own seed (:func:`direction_seed`; the same for every
gate at that direction). With one seed for all, each vertex sees the same hemisphere samples
at every sun, the noise is the same pattern at every direction, and blending neighbouring
directions at a sun between them does not average it out. Measured on the demo room (16 spp,
the bench's 7 held-out suns): the one-bounce part's error fell from 0.028 / 0.034 (file
colours / white walls) to 0.026 / 0.031, at no cost.

Measured (bpy 5.0.1, room test scene): the floor's indirect irradiance off the back wall alone
was 0.0187 (x pi), the pair back wall <- floor added 0.0040; a wall cannot light itself (0).
The materials' specular and textures are not modelled: the bake uses each material's base
colour (Principled Base Color or Diffuse Color; otherwise its viewport colour, reported).

Glossy anchors (``anchors="roughness:R1,..."``): the gated material also mixes in a Principled
metal of its colour with weight ``k1 [depth == 1] + k2 [depth == 2]``; a "gloss" chunk opens
``k1`` on one region at one roughness (the one-bounce light off it as a white metal), and a
truth of a metallic edit sets ``k1 = k2 = metallic`` (:meth:`GatedMaterials.set_finish`).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from ...lt_addon.io.transaction import after_commit
from ...lt_addon.io.versions import REPORT_VERSION
from ...lt_addon.io import atomic
from ...lt_addon.io.names import object_stem
from ...lt_addon.caveats import report_warnings
from ...lt_addon.settings import check_ranges, setting
from ...lt_addon.transport import bounce_transfer, gathered_transfer, ptt
from ...lt_addon.transport.texture import parse_directions
from ..base import cycles_device
from ..base.compat import ensure_node_tree
from ..base.cycles_bake import BakeInputError, EnvironmentBake, SceneChanges, check_memory
from ..base.direct_rays import (DIRECT_BAKES, DIRECT_CHECKS,  # noqa: F401 (tests read it)
                                check_indices, direct_agreement)
from ..base.jobs import Progress, run
from ..base.materials import (finish_sockets, material_bsdf, material_colour,  # noqa: F401
                              material_colour_socket, material_finish, scene_materials)
from ..base.meshes import corner_vertices, polygon_arrays

_PREFIX = "RelightGate"
#: Kind of the bake record on the first object (:func:`..base.blend_files.record_kind`).
KIND = "material_tensors"


def check_regions(scene, regions) -> None:
    """BakeInputError naming the first editable material no rendered mesh of ``scene`` uses."""
    present = {m.name for m in scene_materials(scene) if m is not None}
    missing = [r for r in regions if r not in present]
    if missing:
        raise BakeInputError(f"no rendered mesh in scene {scene.name!r} uses material "
                             f"{missing[0]!r}; materials: {', '.join(sorted(present))}")


class GatedMaterials(SceneChanges):
    """Context manager: every rendered mesh of ``scene`` gets gated Diffuse materials (module
    docstring), restored on exit.

    Parameters
    ----------
    regions : list of str
        Editable material names, region ``i + 1``; every other material is region 0.
    colours : dict, optional
        ``{material name: RGB}`` overriding a material's colour (a truth bake of an edit); by
        default editable regions are white and fixed ones keep their colour.
    """

    def __init__(self, scene, regions: list, colours: dict | None = None,
                 camera_colour: bool = False, gloss: bool = False):
        self.scene, self.regions = scene, list(regions)
        self.colours = dict(colours or {})
        self.camera_colour = camera_colour   # depth 0 in colour too: a render, not a bake
        self.gloss = gloss   # a metal lobe too (glossy anchors, truths of metallic edits)
        self.notes: list[str] = []
        self._restore, self._created = [], []
        self._gates: dict = {}   # region index -> [(g1 socket, g2 socket)]
        self._metal: dict = {}   # material name -> (region, m1, m2, roughness, k0 sockets)

    what = "the materials"

    def _gate_for(self, mat):
        name = mat.name if mat is not None else None
        if name in self._made:
            return self._made[name]
        region = self.regions.index(name) + 1 if name in self.regions else 0
        if name in self.colours:
            colour = np.asarray(self.colours[name], dtype=np.float64)
        elif region:
            colour = np.ones(3)
        else:
            colour, note = material_colour(mat)
            if note:
                self.notes.append(note)
        gate = bpy.data.materials.new(f"{_PREFIX}_{name or 'none'}")
        self._created.append((bpy.data.materials, gate))
        tree = ensure_node_tree(gate)
        nodes, links = tree.nodes, tree.links
        for n in list(nodes):
            nodes.remove(n)
        path = nodes.new("ShaderNodeLightPath")
        depth = []
        for d in range(3):
            c = nodes.new("ShaderNodeMath")
            c.operation = "COMPARE"
            links.new(path.outputs["Ray Depth"], c.inputs[0])
            c.inputs[1].default_value, c.inputs[2].default_value = float(d), 0.5
            depth.append(c)

        def gated(default=0.0):
            """Two Value nodes a, b and the output of a [depth == 1] + b [depth == 2]."""
            a, b = nodes.new("ShaderNodeValue"), nodes.new("ShaderNodeValue")
            a.outputs[0].default_value = b.outputs[0].default_value = default
            first = nodes.new("ShaderNodeMath")
            first.operation = "MULTIPLY"
            links.new(depth[1].outputs[0], first.inputs[0])
            links.new(a.outputs[0], first.inputs[1])
            both = nodes.new("ShaderNodeMath")
            both.operation = "MULTIPLY_ADD"
            links.new(depth[2].outputs[0], both.inputs[0])
            links.new(b.outputs[0], both.inputs[1])
            links.new(first.outputs[0], both.inputs[2])
            return a, b, both

        g1, g2, gate_sum = gated()
        mix = nodes.new("ShaderNodeVectorMath")   # colour * gate + [depth == 0]
        mix.operation = "MULTIPLY_ADD"
        mix.inputs[0].default_value = [float(v) for v in colour]
        camera = None
        if self.camera_colour:      # colour * (gate + k0 [depth == 0]), k0 = 1 - metallic
            camera = nodes.new("ShaderNodeValue")
            camera.outputs[0].default_value = 1.0
            both = nodes.new("ShaderNodeMath")
            both.operation = "MULTIPLY_ADD"
            links.new(depth[0].outputs[0], both.inputs[0])
            links.new(camera.outputs[0], both.inputs[1])
            links.new(gate_sum.outputs[0], both.inputs[2])
            links.new(both.outputs[0], mix.inputs[1])
            mix.inputs[2].default_value = (0.0, 0.0, 0.0)
        else:
            links.new(gate_sum.outputs[0], mix.inputs[1])
            links.new(depth[0].outputs[0], mix.inputs[2])
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        bsdf.inputs["Roughness"].default_value = 0.0
        links.new(mix.outputs[0], bsdf.inputs["Color"])
        out = nodes.new("ShaderNodeOutputMaterial")
        if self.gloss:
            # (1 - f) diffuse + f metal, f = k1 [depth == 1] + k2 [depth == 2]: 0 at the
            # receiver, and a closure of weight 0 is not sampled at all
            k1, k2, f2 = gated()
            rough = nodes.new("ShaderNodeValue")
            rough.outputs[0].default_value = 0.5
            metal = nodes.new("ShaderNodeBsdfPrincipled")
            metal.inputs["Base Color"].default_value = [float(v) for v in colour] + [1.0]
            metal.inputs["Metallic"].default_value = 1.0
            links.new(rough.outputs[0], metal.inputs["Roughness"])
            both = nodes.new("ShaderNodeMixShader")
            links.new(f2.outputs[0], both.inputs[0])
            links.new(bsdf.outputs["BSDF"], both.inputs[1])
            links.new(metal.outputs["BSDF"], both.inputs[2])
            links.new(both.outputs[0], out.inputs["Surface"])
            self._metal[name] = (region, k1.outputs[0], k2.outputs[0], rough.outputs[0],
                                 camera.outputs[0] if camera is not None else None)
        else:
            links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
        self._gates.setdefault(region, []).append((g1.outputs[0], g2.outputs[0]))
        self._made[name] = gate
        return gate

    def _setup(self):
        self._made = {}
        check_regions(self.scene, self.regions)
        if self.gloss:   # a metal's lobe as it is: no glossy blur, its light reaching diffuse
            cyc = self.scene.cycles
            for attr, value in (("blur_glossy", 0.0), ("caustics_reflective", True)):
                old = getattr(cyc, attr)
                self._restore.append(lambda a=attr, v=old: setattr(cyc, a, v))
                setattr(cyc, attr, value)
        for o in self.scene.objects:
            if o.type != "MESH" or o.hide_render:
                continue
            if not o.material_slots:
                o.data.materials.append(self._gate_for(None))
                self._restore.append(lambda m=o.data: m.materials.pop(index=len(m.materials) - 1))
                continue
            for slot in o.material_slots:
                old = slot.material
                if old is not None and old in self._made.values():
                    continue   # a mesh shared with an object already gated
                self._restore.append(lambda s=slot, m=old: setattr(s, "material", m))
                slot.material = self._gate_for(old)
        self.set_gates(None, None)

    def set_gates(self, last: int | None, before: int | None = None) -> None:
        """Let light reflect last off region ``last`` and before that off region ``before``
        (None: off nothing; ``"all"``: off every region)."""
        for region, sockets in self._gates.items():
            for g1, g2 in sockets:
                g1.default_value = float(last == "all" or last == region)
                g2.default_value = float(before == "all" or before == region)
        for _, m1, m2, _, _ in self._metal.values():
            m1.default_value = m2.default_value = 0.0

    def set_metal(self, region: int, roughness: float) -> None:
        """Let light reflect last off region ``region`` as a metal of ``roughness`` (its colour,
        metallic 1) and off nothing else: a glossy anchor's bake (needs ``gloss``)."""
        self.set_gates(None, None)
        for reg, m1, _, rough, _ in self._metal.values():
            m1.default_value = float(reg == region)
            rough.default_value = float(roughness)

    def set_finish(self, finish: dict) -> None:
        """Give materials ``{name: (metallic, roughness)}`` at every bounce (a truth bake of a
        metallic edit; after :meth:`set_gates`): ``(1 - m)`` diffuse plus ``m`` metal. With
        ``camera_colour`` the camera sees only the diffuse part, as the preview shows it."""
        for name, (m, rho) in finish.items():
            if name in self._metal:
                _, m1, m2, rough, camera = self._metal[name]
                m1.default_value = m2.default_value = float(m)
                rough.default_value = float(rho)
                if camera is not None:
                    camera.default_value = 1.0 - float(m)



def receivers(objects, regions: list, domain: str = "POINT"
              ) -> tuple[np.ndarray, np.ndarray, list]:
    """Per stacked vertex (or face corner with ``domain="CORNER"``): region (V,) int16 of the
    face material it belongs to (the largest face area wins at a shared vertex) and the
    diffuse colour (V, 3) float32 that material bakes with; plus the notes of
    :func:`material_colour`."""
    region_of, colour_of, notes = [], [], []
    for o in objects:
        mesh = o.data
        mats = [s.material for s in o.material_slots] or [None]
        reg = np.array([regions.index(m.name) + 1 if m is not None and m.name in regions else 0
                        for m in mats], dtype=np.int16)
        col = []
        for m in mats:
            c, note = material_colour(m)
            col.append(c)
            if note and note not in notes:
                notes.append(note)
        col = np.array(col, dtype=np.float32)
        F = len(mesh.polygons)
        mi = np.zeros(F, dtype=np.int64)
        if F:
            mesh.polygons.foreach_get("material_index", mi)
        mi = np.clip(mi, 0, len(mats) - 1)
        area, start, total = polygon_arrays(mesh)
        loops = corner_vertices(mesh)
        by_start = np.argsort(start, kind="stable")   # a face's corners are contiguous
        face_of_loop = np.repeat(by_start, total[by_start])
        if domain == "CORNER":
            region_of.append(reg[mi[face_of_loop]])
            colour_of.append(col[mi[face_of_loop]])
            continue
        best = np.full(len(mesh.vertices), -1.0)
        slot = np.zeros(len(mesh.vertices), dtype=np.int64)
        order = np.argsort(area[face_of_loop], kind="stable")   # larger faces write last
        v, f = loops[order], face_of_loop[order]
        best[v], slot[v] = area[f], mi[f]
        region_of.append(reg[slot])
        colour_of.append(col[slot])
    return np.concatenate(region_of), np.concatenate(colour_of), notes


#: How the diffuse bounce terms are made: gathered by rays once for every light direction
#: (:mod:`.bounce_rays`, the default) or a Cycles bake per direction, region and gate.
BOUNCE_BAKES = ("rays", "cycles")
#: The one-bounce directions when none are given. Cycles bakes: measured with the smoothing,
#: 128 at 16 spp erred 9% less than 64 at 32 spp for less bake time. Gathered by rays: the
#: blend between directions is made exact at a sun by the receiver transfer
#: (:class:`..lt_addon.transport.gathered_transfer.ReceiverTransfer`), so 128 erred as 400
#: (demo room, 7 held-out suns: 0.0167 against 0.0166 of E) in 44 MiB instead of 67.
ONE_BOUNCE = "hemi:128"
#: Fewer one-bounce directions than this blend a sun's bounce light coarsely: the bake's notes
#: say so (the test room, 7 held-out suns, 256-spp truths, 16 direct directions, bounces by
#: rays: 4 directions 6.7x the noise floor, 32 1.75x, 128 1.31x).
COARSE_ONE_BOUNCE = 64
#: The glossy anchors' directions when none are given with rays (with Cycles: the one-bounce
#: set, as before), one Cycles bake per region, anchor and direction.
ANCHOR_DIRECTIONS = "hemi:128"


@dataclass
class MaterialBakeSettings:
    """What ``bake-materials`` bakes.

    regions : editable material names; anchors : "diffuse" (colour edits) or
    "roughness:R1,R2,..." (also metallic / roughness edits: a glossy anchor per region and
    roughness, :mod:`..lt_addon.transport.ptt`); anchor_samples : Cycles samples of the
    glossy anchors' bakes (a metal's reflected sun is a caustic: noisier than the diffuse
    bounce terms); anchor_directions : their direction set (None: :data:`ANCHOR_DIRECTIONS`
    with rays, the one-bounce set with Cycles);
    bounces : 1 or 2; directions : specs of the direct, one- and two-bounce direction sets
    (``hemi:N[:P]``; the one-bounce one None: :data:`ONE_BOUNCE`);
    bounce_bake : "rays" (the diffuse bounce terms gathered by ``rays`` cosine-weighted rays
    per receiver, :mod:`.bounce_rays`) or "cycles" (a Cycles bake per direction, region and
    gate at ``samples`` per vertex); direct : how the direct term is made (:data:`DIRECT_BAKES`:
    by rays through the ray engine, :class:`..base.direct_rays.ReceiverRays`, or a 1-sample
    Cycles bake per direction, exact under a hard Sun); seed : base of the Cycles seed of
    each direction (:func:`direction_seed`) and of the rays' lattice shifts; domain : "POINT" (a
    value per vertex) or "CORNER" (per face corner: hard edges stay hard, about 4x the data
    on quad meshes); smoothing : radius, in median receiver spacings, over which the
    Cycles-baked bounce terms (and glossy anchors) are averaged after the bake (0: off;
    :mod:`..lt_addon.transport.bounce_transfer`, which also composes the two-bounce light; not
    part of the chunk key: the chunks a cancelled bake kept serve any smoothing; the file holds
    only the smoothed terms).
    """

    regions: list = field(default_factory=list)
    anchors: str = setting(
        "diffuse", metavar="diffuse|roughness:R1,R2,...", panel=False,
        help="material anchors per region: 'diffuse' (colour edits) or 'roughness:0.4,0.8' "
             "(also metallic and roughness edits of a Principled material: one more one-bounce "
             "bake per region, anchor and direction, the region reflecting as a metal of that "
             "roughness; a roughness between anchors blends them). Below about 0.4 a metal's "
             "reflected sun is a caustic: raise the anchor samples")
    anchor_samples: int = setting(
        64, lo=1, hi=65536, label="Anchor Samples",
        help="Cycles samples of the glossy anchors' bakes (a metal's reflected sun is noisier "
             "than diffuse light; measured on the demo room: 16 left the metal's light on the "
             "floor blotchy)")
    bounces: int = setting(
        2, lo=1, hi=2, choices=None,
        help="Path orders baked per editable material: 1 = one bounce, 2 = also ordered pairs "
             "(the colour bleeding between two edited walls)")
    directions: tuple = ("hemi:400:1.5", None, "hemi:8")
    samples: int = setting(
        16, lo=1, hi=65536,
        help="Cycles samples per vertex of each bounce term with Cycles bounces (16 with 128 "
             "one-bounce directions: measured on the demo room, more accurate than 32 with 64)")
    seed: int = setting(0, lo=0, panel=False, help="Cycles seed")
    domain: str = "POINT"
    smoothing: float = setting(
        bounce_transfer.SMOOTH_SPACINGS, lo=0.0, hi=20.0, metavar="SPACINGS",
        help="Average the Cycles-baked bounce terms and glossy anchors over this many median "
             "vertex spacings after the bake (0: off; never across differently facing "
             "surfaces, never over 3% of the scene; the gathered ones are not noise-bound and "
             "stay as they are). Measured on the demo room: the 32-sample one-bounce term's "
             "error at baked directions went from 0.030-0.039 to 0.014-0.022. Not in the chunk "
             "key: kept chunks of a cancelled bake serve any smoothing")
    bounce_bake: str = setting("rays", label="Bounces By", choices=(
        ("rays", "Rays", "every receiver casts rays once and the transfer they gather serves "
                         "every sun direction (measured on the demo room at 7 held-out suns: "
                         "0.93x the noise floor of two Cycles truths in 48 s)"),
        ("cycles", "Cycles", "a Cycles bake per sun direction, region and gate at the bounce "
                             "samples (1.9x the noise floor in 168 s)")),
        help="How the diffuse bounce terms are made")
    direct: str = setting("auto", label="Direct By", choices=(
        ("auto", "Auto", "rays where they reproduce the scene (no instanced, see-through or "
                         "displaced shadow casters), else Cycles; the report says which and why"),
        ("rays", "Rays", "a shadow ray per receiver and direction (Embree); refuse a scene "
                         "rays cannot reproduce"),
        ("cycles", "Cycles", "a 1-sample Cycles bake per direction: the reference path")),
        help="How the direct light is baked")
    rays: int = setting(
        gathered_transfer.DEFAULT_RAYS, lo=16, hi=65536,
        help="Rays per receiver of the gathered bounce terms (512; 256 / 1024 measured 1.16x / "
             "1.12x the floor before the receiver transfer)")
    anchor_directions: str | None = setting(
        None, metavar="SPEC", panel=False,
        help="sun directions of the glossy anchors' bakes (default hemi:128; with Cycles "
             "bounces the one-bounce set)")

    def specs(self) -> tuple:
        """The direct, one- and two-bounce direction specs (a one-bounce None:
        :data:`ONE_BOUNCE`)."""
        d0, d1, d2 = self.directions
        return (d0, d1 or ONE_BOUNCE, d2)

    def anchor_spec(self) -> str:
        """The glossy anchors' direction spec (:attr:`anchor_directions` resolved)."""
        if self.anchor_directions:
            return self.anchor_directions
        return ANCHOR_DIRECTIONS if self.bounce_bake == "rays" else self.specs()[1]

    @property
    def gathers(self) -> bool:
        """The diffuse bounce terms are gathered by rays (not Cycles bakes)."""
        return self.bounce_bake == "rays" and self.bounces >= 1

    def validate(self) -> list:
        if not self.regions:
            raise BakeInputError("name at least one editable material (--region MATERIAL)")
        if len(set(self.regions)) != len(self.regions):
            raise BakeInputError("a --region is given twice")
        try:
            ptt.parse_anchors(self.anchors)
        except ValueError as exc:
            raise BakeInputError(str(exc)) from None
        if self.bounces not in (1, 2):
            raise BakeInputError(f"bounces must be 1 or 2, got {self.bounces}")
        if self.samples < 1 or self.anchor_samples < 1:
            raise BakeInputError(f"samples must be >= 1, got {self.samples} and "
                                 f"{self.anchor_samples} for the glossy anchors")
        if not 0.0 <= self.smoothing <= 20.0:
            raise BakeInputError(f"smoothing must be 0..20 receiver spacings, got "
                                 f"{self.smoothing}")
        if self.domain not in ("POINT", "CORNER"):
            raise BakeInputError(f"domain must be POINT or CORNER, got {self.domain!r}")
        if self.bounce_bake not in BOUNCE_BAKES:
            raise BakeInputError(f"bounce bake must be one of {', '.join(BOUNCE_BAKES)}, got "
                                 f"{self.bounce_bake!r}")
        if self.direct not in DIRECT_BAKES:
            raise BakeInputError(f"direct must be one of {', '.join(DIRECT_BAKES)}, got "
                                 f"{self.direct!r}")
        if not 16 <= int(self.rays) <= 65536:
            raise BakeInputError(f"rays must be 16..65536 per receiver, got {self.rays}")
        check_ranges(self)
        try:
            parse_directions(self.anchor_spec())
            return [parse_directions(s) for s in self.specs()]
        except ValueError as exc:
            raise BakeInputError(f"bad direction set: {exc}") from None

    @property
    def roughness(self) -> tuple:
        """The glossy anchors' roughness values (() for "diffuse")."""
        return ptt.parse_anchors(self.anchors)


#: Directions per chunk (as the transport bakes'): a cancelled bake resumes from its finished
#: chunks, and a distributed one hands out pieces of similar Cycles time.
CHUNK_DIRECTIONS = 16


@dataclass(frozen=True)
class MaterialChunk:
    """Directions ``start:stop`` of one term of a material bake, baked with the gates open on
    region ``last`` (the surface the light reflects off last) and ``before`` (the one before).

    ``kind``: "direct" (gates closed; the direct set, 1 spp), "one" (one bounce off ``last``;
    the one-bounce set), "ref" (one bounce off ``last`` over the two-bounce set: what the pairs
    of ``last`` subtract), "pair" (``before`` -> ``last``, raw: the "ref" of ``last`` is
    subtracted when the tensors are assembled, so every chunk is a plain Cycles bake) or
    "gloss" (one bounce off region ``last`` as a white metal of the ``before``-th roughness
    anchor; the anchors' set) or "gather" (no Cycles call: the rays of the gather origins
    ``start:stop``, :mod:`.bounce_rays`; one step of progress) or "check" (as "direct", at
    the :func:`check_indices` of the direct set: Cycles' check of a direct term made by rays).
    """

    kind: str
    last: int | None
    before: int | None
    start: int
    stop: int

    @property
    def name(self) -> str:
        """Chunk-cache name, e.g. ``pair_r1_r2_00016`` (light off region 1, then region 2)."""
        if self.kind == "gather":
            return f"gather_{self.start:07d}"
        if self.kind == "gloss":
            return f"gloss_r{self.last}_a{self.before}_{self.start:05d}"
        regions = "".join(f"_r{r}" for r in (self.before, self.last) if r is not None)
        return f"{self.kind}{regions}_{self.start:05d}"

    @property
    def part(self) -> tuple:
        """What a worker needs besides ``start, stop``: ``(kind, last, before)``."""
        return (self.kind, self.last, self.before)

    def __len__(self) -> int:
        """Steps of progress: Cycles calls (one per direction), or 1 for a gather chunk."""
        return 1 if self.kind == "gather" else self.stop - self.start

    def shape(self, V: int) -> tuple | None:
        """The chunk's array: (n, V) irradiance for "direct", (n, V, 3) RGB otherwise
        (float32, E per unit normal irradiance); None for "gather" (its transfer entries,
        as many as the rays hit distinct corners)."""
        if self.kind == "gather":
            return None
        return (self.stop - self.start, V) if self.kind in ("direct", "check") else (
            self.stop - self.start, V, 3)

    def fits(self, arr, V: int) -> bool:
        """``arr`` (a kept chunk) is what this chunk bakes."""
        if self.kind == "gather":
            return arr.dtype == gathered_transfer.ENTRY and arr.ndim == 1
        return arr.shape == self.shape(V)


def direction_seed(seed: int, s: int) -> int:
    """Cycles seed of direction ``s`` of a bake whose settings say ``seed``: a different one
    per direction (see the module docstring), the same for every gate and process."""
    return int((int(seed) * 1_000_003 + int(s)) % 2_147_483_647)


def material_chunks(settings: MaterialBakeSettings, sizes: tuple, origins: int = 0,
                    direct_rays: bool = False) -> list:
    """The chunks of a material bake in the order one process bakes them (a gate change makes
    Cycles sync the shaders again, about 0.25 s a call here, a new direction does not: gates
    outside, directions inside). ``sizes``: (S0, S1, S2, Sg) directions per path order and of
    the glossy anchors (0: none); ``origins``: the gather's ray origins (bounces by rays:
    :func:`.bounce_rays.gather_chunks` replace the one- and two-bounce Cycles chunks);
    ``direct_rays``: rays make the direct term, Cycles bakes only its "check" directions."""
    S0, S1, S2, Sg = sizes
    R1 = len(settings.regions) + 1

    def runs(kind, S, last=None, before=None):
        return [MaterialChunk(kind, last, before, a, min(a + CHUNK_DIRECTIONS, S))
                for a in range(0, S, CHUNK_DIRECTIONS)]

    out = runs("check", len(check_indices(S0))) if direct_rays else runs("direct", S0)
    gathers = settings.gathers
    for r in range(R1 if S1 and not gathers else 0):
        out += runs("one", S1, r)
    for r in range(1, R1 if S1 and Sg else 0):
        for k in range(len(settings.roughness)):
            out += runs("gloss", Sg, r, k)
    for r2 in range(R1 if S2 and not gathers else 0):
        out += runs("ref", S2, r2)
        for r1 in range(R1):
            out += runs("pair", S2, r2, r1)
    if gathers:
        from .bounce_rays import gather_chunks

        out += [MaterialChunk("gather", None, None, a, b) for a, b in gather_chunks(origins)]
    return out


def bake_material_chunks(scene, objects, settings: MaterialBakeSettings, chunks, put,
                         threads: int = 0):
    """Generator: bake ``chunks`` (:class:`MaterialChunk`, in :func:`material_chunks` order)
    with gated materials, handing each finished one to ``put(name, array)``; yields
    ``(chunk, direction index)`` after every Cycles call and returns Cycles' seconds.
    ``threads``: Cycles threads (0: all cores). Used by the bake, the Dask task and farms."""
    sets = {k: d.directions for k, d in zip(("direct", "one", "ref"), settings.validate())}
    sets["pair"] = sets["ref"]
    sets["gloss"] = parse_directions(settings.anchor_spec()).directions
    sets["check"] = sets["direct"][check_indices(len(sets["direct"]))]
    roughness = settings.roughness
    if threads:   # workers sharing a machine: no more Cycles threads than their share of cores
        scene.render.threads_mode, scene.render.threads = "FIXED", int(threads)
    cycles = 0.0
    gathers = [c for c in chunks if c.kind == "gather"]
    if gathers:   # rays, no Cycles: before the gates change the materials
        from .bounce_rays import GatherScene

        gs = GatherScene(scene, settings.regions)
        for c in gathers:
            put(c.name, gs.gather(c.start, c.stop, settings.rays, settings.seed))
            yield c, c.start
        chunks = [c for c in chunks if c.kind != "gather"]
    if not chunks:
        return cycles
    with GatedMaterials(scene, settings.regions, gloss=bool(roughness)) as gates:
        group = {"direct": 0, "check": 0, "gloss": 2}
        for g, spp in enumerate((1, settings.samples, settings.anchor_samples)):
            mine = [c for c in chunks if group.get(c.kind, 1) == g]
            if not mine:
                continue
            direct = g == 0
            kw = ({} if direct else {"passes": "indirect"})
            with EnvironmentBake(scene, objects, None, spp, 0 if direct else settings.bounces,
                                 (8, 16),
                                 mode="irradiance", seed=settings.seed, world_sampling="none",
                                 domain=settings.domain, **kw) as session:
                for c in mine:
                    if c.kind == "gloss":
                        gates.set_metal(c.last, roughness[c.before])
                    else:
                        gates.set_gates(c.last, c.before)
                    rows = []
                    for s in range(c.start, c.stop):
                        # the session put the scene's own seed aside and restores it
                        session.scene.cycles.seed = direction_seed(settings.seed, s)
                        e = np.pi * np.concatenate(
                            session.bake_sun_all(sets[c.kind][s], 1.0, 0.0), axis=0)
                        rows.append(e[:, 0] if direct else e)   # E per unit irradiance
                        yield c, s
                    put(c.name, np.stack(rows).astype(np.float32, copy=False))
                cycles += session.bake_seconds
    return cycles


def direct_rays(scene, objects, settings: MaterialBakeSettings):
    """``(choice, rays)`` of the direct term for ``objects``' receivers
    (:func:`..base.direct_rays.bake_rays`)."""
    from ..base.direct_rays import bake_rays

    return bake_rays(scene, [(o.name, element_count(o, settings.domain)) for o in objects],
                     settings.domain, settings.direct)


def material_stage(scene, objects, settings: dict, start: int, stop: int, cache,
                   threads: int = 0, part=None) -> float:
    """The material bake's chunk function for :func:`..farm.distributed.fill_chunks`: the
    :class:`MaterialChunk` ``part + (start, stop)`` of the MaterialBakeSettings ``settings``
    (sent as a dict) into ``cache``; returns Cycles' seconds."""
    return run(bake_material_chunks(scene, objects, MaterialBakeSettings(**settings),
                                    [MaterialChunk(*part, start, stop)], cache.put, threads))


def colour_notes(scene, regions) -> list:
    """Why a fixed material of ``scene`` bakes with its viewport colour (see
    :func:`material_colour`), one note per such material."""
    return [note for m in scene_materials(scene)
            if (m is None or m.name not in regions)
            for note in [material_colour(m)[1]] if note]


def material_chunk_cache(scene, objects, settings: MaterialBakeSettings, out_dir: str):
    """The chunk cache of a material bake of ``objects`` into ``out_dir``: ``<out_dir>/
    .relight_cache/<first object>_materials/``, keyed by the scene content (every rendered
    mesh reflects light: :func:`.bake_inputs.scene_key`) and the settings; stale keys go."""
    import dataclasses

    from ...lt_addon.io.chunk_cache import ChunkCache
    from ..base.bake_inputs import scene_key
    from ..base.cycles_device import current
    from ..base.bake_inputs import cache_root

    baked = {k: v for k, v in dataclasses.asdict(settings).items() if k != "smoothing"}
    # what the chunks depend on, defaults resolved (a panel and a command line that mean the
    # same bake share its chunks): the rays' count only with rays, the Cycles samples of the
    # bounce terms only without, the anchors' set only with anchors
    baked["directions"] = list(settings.specs())
    baked["anchor_directions"] = settings.anchor_spec() if settings.roughness else None
    baked.pop("samples" if settings.gathers else "rays")
    if settings.gathers:   # the gather's hits from Embree and from mathutils differ in last bits
        from ...lt_addon.rays import engine

        ok, name = engine.available()
        baked["gather_engine"] = name if ok else "mathutils"
    key = {"stage": "materials", "scene": scene_key(scene, list(objects)),
           "device": current().id, "settings": baked, "chunk_directions": CHUNK_DIRECTIONS,
           "seeds": "per direction"}   # chunks of the one-seed bakes are not these
    folder = object_stem(objects[0].name) + "_materials"
    cache = ChunkCache(os.path.join(cache_root(out_dir), folder), key)
    cache.prune_others(adopt_devices=current().mix_devices)   # --mix-devices
    return cache


def bake_materials(scene, objects, settings: MaterialBakeSettings, cache=None, client=None,
                   blend_path: str | None = None):
    """Generator: bake the transfer tensors of ``objects`` (receivers; every rendered mesh of
    the scene reflects light); yields Progress per Cycles call (and gather chunk), returns a
    :class:`..lt_addon.transport.ptt.TransferTensors`.

    The bake is the :func:`material_chunks` list. With a chunk ``cache``
    (:func:`material_chunk_cache`) each finished chunk is kept and a rerun reuses it (bit for
    bit: same seed, same Cycles calls, same rays); with a Dask ``client`` too, the missing
    chunks are baked on its workers from the saved ``blend_path``. ``metadata["chunks"]`` has
    the figures. With bounces by rays (the default) the one- and two-bounce terms come from the
    gathered transfer (:func:`gathered_terms`) once the chunks are in."""
    d0, d1, d2 = settings.validate()
    objects = list(objects)
    check_regions(scene, settings.regions)
    if client is not None and (cache is None or not blend_path):
        raise BakeInputError("a distributed bake needs the chunk cache and a saved .blend the "
                             "workers can open")
    started = time.perf_counter()
    V = sum(element_count(o, settings.domain) for o in objects)
    R1 = len(settings.regions) + 1
    K = len(settings.roughness)
    S1 = d1.size if settings.bounces >= 1 else 0
    S2 = d2.size if settings.bounces >= 2 else 0
    dg = parse_directions(settings.anchor_spec())
    Sg = dg.size if K and S1 else 0
    direct_by, receiver_rays = direct_rays(scene, objects, settings)
    by_rays = receiver_rays is not None
    checks = check_indices(d0.size) if by_rays else None
    gs = None
    if settings.gathers:
        from .bounce_rays import GatherScene

        try:
            gs = GatherScene(scene, settings.regions)
            gs.receiver_matrix(objects, settings.domain)   # every receiver is seen by the rays
        except ValueError as exc:
            raise BakeInputError(str(exc)) from None
    # the glossy chunks arrive in RGB (3 values) and are averaged only when assembled
    floats = V * (d0.size + 3 * R1 * S1 + 3 * (R1 - 1) * K * Sg + 3 * R1 * R1 * S2)
    if gs is not None:   # the transfer: ~3 entries of 16 bytes per ray that hits something
        floats += 12 * gs.origins * settings.rays
    check_memory(floats * 4 * 2, f"{V} vertices x {floats // max(V, 1)} term values",
                 "use fewer regions or coarser direction sets")
    plan = material_chunks(settings, (d0.size, S1, S2, Sg), gs.origins if gs else 0, by_rays)
    total = sum(len(c) for c in plan) + (d0.size if by_rays else 0)
    calls = ptt.bake_count(d0.size, S1, S2, R1 - 1, settings.bounces, K, Sg,
                           rays=settings.gathers) - (d0.size - len(checks) if by_rays else 0)
    assert calls == sum(len(c) for c in plan if c.kind != "gather")
    have = {}
    for c in plan if cache is not None else ():
        arr = cache.get(c.name)
        if arr is not None and c.fits(arr, V):
            have[c.name] = arr
    reused = len(have)
    done = sum(len(c) for c in plan if c.name in have)
    if reused:
        yield Progress(done, total, f"{reused} of {len(plan)} chunks kept by an earlier bake")
    distributed = None
    if client is not None and reused < len(plan):
        from ..farm.distributed import fill_chunks

        todo = [c for c in plan if c.name not in have]
        distributed = yield from fill_chunks(client, blend_path, objects, settings, cache,
                                             todo, done, total, material_stage)
        for c in todo:
            arr = cache.get(c.name)
            if arr is not None and c.fits(arr, V):
                have[c.name] = arr
                done += len(c)
    todo = [c for c in plan if c.name not in have]
    seconds = {}

    def put(name, arr):
        have[name] = arr
        if cache is not None:
            cache.put(name, arr)

    cycles = 0.0
    if todo:
        what = {"direct": "direct", "check": "direct: Cycles' check of the rays",
                "one": "one bounce off region {last}",
                "gloss": "one bounce off region {last} as metal, anchor {before}",
                "ref": "two bounces: reference {last}", "pair": "two bounces {before}->{last}",
                "gather": "bounce rays"}
        stage = {"direct": "direct", "check": "direct_check", "one": "one_bounce",
                 "gloss": "glossy_anchors",
                 "ref": "two_bounce", "pair": "two_bounce", "gather": "bounce_rays"}
        gen = bake_material_chunks(scene, objects, settings, todo, put)
        t = time.perf_counter()
        try:
            while True:
                c, s = next(gen)
                now = time.perf_counter()
                seconds[stage[c.kind]] = seconds.get(stage[c.kind], 0.0) + now - t
                done += 1
                where = (f"origins {c.start + 1}-{c.stop} of {gs.origins if gs else c.stop}, "
                         f"{settings.rays} each" if c.kind == "gather" else f"direction {s + 1}")
                yield Progress(done, total, f"{what[c.kind].format(last=c.last, before=c.before)}"
                                            f", {where}")
                t = time.perf_counter()
        except StopIteration as stop:
            cycles = stop.value
    direct = np.empty((d0.size, V), dtype=np.float32)
    if by_rays:   # every direction, a shadow ray per receiver corner (no cache: seconds)
        t = time.perf_counter()
        for a in range(0, d0.size, CHUNK_DIRECTIONS):
            b = min(a + CHUNK_DIRECTIONS, d0.size)
            direct[a:b] = receiver_rays.bake_rows(d0.directions[a:b])
            done += b - a
            yield Progress(done, total, f"direct by rays, directions {a + 1}-{b}/{d0.size}")
        seconds["direct"] = time.perf_counter() - t
        cycles_rows = np.concatenate([have[c.name] for c in plan if c.kind == "check"])
        direct_by.update(checked_directions=len(checks), vs_cycles=direct_agreement(
            cycles_rows, direct[checks]), rays=int(receiver_rays.engine.rays))
    one = np.zeros((S1, 3, R1 if S1 else 0, V), dtype=np.float32)
    two = np.zeros((S2, 3, R1 if S2 else 0, R1 if S2 else 0, V), dtype=np.float32)
    gloss = np.zeros((Sg, R1 - 1, K, V), dtype=np.float32) if Sg else None
    for c in plan:
        arr, rows = have[c.name], slice(c.start, c.stop)
        if c.kind == "direct":
            direct[rows] = arr
        elif c.kind == "one":
            one[rows, :, c.last] = arr.transpose(0, 2, 1)
        elif c.kind == "gloss":   # white sun, white metal: the channels agree but for noise
            gloss[rows, c.last - 1, c.before] = arr.mean(axis=2)
        elif c.kind == "pair":   # the light that took the second bounce (>= 0 up to noise)
            ref = have[MaterialChunk("ref", c.last, None, c.start, c.stop).name]
            two[rows, :, c.before, c.last] = np.maximum(arr - ref, 0.0).transpose(0, 2, 1)
    notes = colour_notes(scene, settings.regions)
    if 0 < S1 < COARSE_ONE_BOUNCE:
        notes.append(f"{S1} one-bounce directions: a sun between them gets a coarse blend of "
                     f"the bounce light (measured on the test room at held-out suns: 4 "
                     f"directions 6.7x, 32 1.75x, 128 (the default) 1.31x the noise of two "
                     f"Cycles renders); with --bounce-bake rays more directions cost only "
                     f"memory")
    region_of, colour_of, more = receivers(objects, settings.regions, settings.domain)
    base = np.array([material_colour(bpy.data.materials[r])[0] for r in settings.regions])
    finish = np.array([material_finish(bpy.data.materials[r]) for r in settings.regions])
    chunks = {"chunks_total": len(plan), "chunks_reused": reused,
              "chunk_directions": CHUNK_DIRECTIONS,
              "chunks_rejected": cache.rejected if cache is not None else 0}
    if distributed is not None:
        chunks["distributed"] = distributed
    meta = {"anchors": settings.anchors, "bounces": settings.bounces, "domain": settings.domain,
            "bounce_bake": settings.bounce_bake,
            "samples": settings.samples if not settings.gathers else None,
            "rays": settings.rays if settings.gathers else None,
            "seed": settings.seed, "bake_calls": calls, "direct": direct_by,
            "anchor_samples": settings.anchor_samples if K else None,
            "seconds": {k: round(v, 3) for k, v in seconds.items()},
            "cycles_seconds": round(cycles, 3),
            "bake_seconds": round(time.perf_counter() - started, 3), "chunks": chunks,
            "notes": notes + [n for n in more if n not in notes]}
    observations = direct_one = None
    if gs is not None:
        t = time.perf_counter()
        transfer = gs.transfer([have[c.name] for c in plan if c.kind == "gather"], objects,
                               settings.domain)
        terms = yield from gathered_terms(gs, transfer, d1, d2 if S2 else None, total)
        one, two, direct_one, observations = (terms[k] for k in ("one", "two", "direct_one",
                                                                  "observations"))
        seconds["bounce_terms"] = round(time.perf_counter() - t, 3)
        meta["gather"] = {"rays_per_origin": settings.rays, "origins": gs.origins,
                          "corners": gs.corners, "transfer_entries": int(transfer.K.nnz),
                          "sky_fraction": round(transfer.sky_fraction(), 4),
                          "back_sides_lit": int(transfer.back_sides().sum()),
                          "fit_two_directions": terms["fit_spec"]}
        if d1.spec == d0.spec and not by_rays:   # the rays' direct light against Cycles' own
            meta["gather"]["direct_vs_cycles"] = direct_agreement(direct, direct_one)
        meta["notes"] += [n for n in gs.notes if n not in meta["notes"]]
    tensors = ptt.TransferTensors(direct, one, two, tuple(d.spec for d in (d0, d1, d2)),
                                  list(settings.regions), base, region_of, colour_of,
                                  [(o.name, element_count(o, settings.domain)) for o in objects],
                                  meta, roughness=settings.roughness if gloss is not None else (),
                                  gloss=gloss, base_finish=finish,
                                  gloss_spec=dg.spec if gloss is not None else None)
    if gs is not None:
        t = time.perf_counter()
        tensors = yield from bounce_terms(scene, tensors, settings.smoothing, total,
                                          direct_one=direct_one, observations=observations)
        tensors.metadata["bounce_transfer"]["seconds"] = round(time.perf_counter() - t, 3)
        source = np.ones((V, 3), np.float32)   # editable receivers: the edit is the coefficient
        source[region_of == 0] = colour_of[region_of == 0]
        pos = np.asarray(transfer.receivers @ gs.front.points)          # (V, 3)
        diagonal = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0))) if V else 0.0
        tensors.receiver_transfer = transfer.receiver_transfer(
            source, direct_one, pos, gathered_transfer.NEAR_FRACTION * diagonal)
        tensors.metadata["gather"]["receiver_transfer"] = {
            "radius_m": round(gathered_transfer.NEAR_FRACTION * diagonal, 4),
            "entries": int(tensors.receiver_transfer.matrix.nnz)}
    elif S1 and settings.smoothing + bounce_transfer.composes(S1, S2) > 0:
        t = time.perf_counter()
        tensors = yield from bounce_terms(scene, tensors, settings.smoothing, total)
        tensors.metadata["bounce_transfer"]["seconds"] = round(time.perf_counter() - t, 3)
    tensors.metadata["bake_seconds"] = round(time.perf_counter() - started, 3)
    return tensors


#: Two-bounce directions the second-bounce composition is fitted to when the bounce terms are
#: gathered (exact at any direction, so a finer set than the stored two-bounce term; not kept).
FIT_TWO_DIRECTIONS = "hemi:64"
#: Patches per region of that composition. Measured on the demo room with gathered terms, 7
#: held-out suns (error of E): 0.0177 / 0.0182 at 64 / 32 patches (0.98x / 1.01x the noise
#: floor). Chosen when an update spread each pair's patches over the receivers (32 halved
#: that part, about 1.5 of 3 ms at 13K vertices); since the update weighs the patches first
#: (BounceTransfer.contract, 0.2 ms) 64 would cost little there: not re-measured yet.
GATHER_PATCHES = 32
#: Weight of the two-bounce observations in that fit (relative to equal total weight; measured
#: there: the two-bounce part's error 0.0114 / 0.0103 / 0.0102 at 0.3 / 1 / 3: exact
#: observations may pull harder than the noisy Cycles bakes, bounce_transfer.TWO_WEIGHT).
GATHER_TWO_WEIGHT = 1.0
#: Directions per block of the gathered terms (bounds the corner arrays' memory).
_BLOCK = 32


def gathered_terms(gs, transfer, d1, d2, of: int):
    """Generator (Progress, at ``of`` of ``of``: the bake's bar stays full): the one-bounce term
    (S1, 3, R+1, V) at ``d1``, the two-bounce term (S2, 3, R+1, R+1, V) at ``d2`` (None: one
    bounce), the exact direct term at ``d1`` (S1, V) and the fit's observations (one- and
    two-bounce light at :data:`FIT_TWO_DIRECTIONS`), all from the gathered ``transfer``
    (:class:`..lt_addon.transport.gathered_transfer.GatheredTransfer`) and the exact direct
    light at every corner by rays (:meth:`.bounce_rays.GatherScene.direct`)."""
    back = transfer.back_sides()
    R1, V = transfer.regions, transfer.receivers.shape[0]
    fit = parse_directions(FIT_TWO_DIRECTIONS) if d2 is not None else None
    out = {"one": np.zeros((d1.size, 3, R1, V), np.float32),
           "direct_one": np.zeros((d1.size, V), np.float32),
           "two": np.zeros((d2.size if d2 else 0, 3, R1 if d2 else 0, R1 if d2 else 0, V),
                           np.float32), "observations": None,
           "fit_spec": fit.spec if fit is not None else None}
    if fit is not None:
        obs = (np.zeros((fit.size, 3, R1, V), np.float32),
               np.zeros((fit.size, 3, R1, R1, V), np.float32))
    jobs = [("one", d1)] + ([("two", d2), ("fit", fit)] if d2 is not None else [])
    count, n = sum(d.size for _, d in jobs), 0
    for name, dset in jobs:
        for a in range(0, dset.size, _BLOCK):
            rows = slice(a, min(a + _BLOCK, dset.size))
            front, behind = gs.direct(dset.directions[rows], back)
            one_c = transfer.one_bounce_corners(front, behind)
            if name == "one":
                out["one"][rows] = transfer.to_receivers(one_c)
                out["direct_one"][rows] = transfer.to_receivers(front)
            else:
                two_c = transfer.to_receivers(transfer.two_bounce_corners(one_c))
                if name == "two":
                    out["two"][rows] = two_c
                else:
                    obs[0][rows], obs[1][rows] = transfer.to_receivers(one_c), two_c
            n += rows.stop - rows.start
            yield Progress(of, of, f"bounce terms from the rays: direct light at "
                                   f"{n} of {count} directions")
    if fit is not None:
        out["observations"] = obs
    return out


def bounce_terms(scene, tensors, smoothing: float, of: int | None = None, direct_one=None,
                 observations=None):
    """Generator (Progress per one-bounce direction; with ``of``, the finished bake's
    ``of / of`` so that a progress bar does not start again): returns ``tensors`` with
    smoothed bounce terms and a fitted second-bounce composition
    (:func:`..lt_addon.transport.ptt.with_bounce_transfer`); the receivers' positions and
    normals, and the exact direct light at the one-bounce directions, come from a
    :class:`.direct_rays.ReceiverRays` of the scene (a ray per receiver and direction). When
    the receivers' evaluated meshes do not match the bake (a modifier that changes the vertex
    count) the tensors are returned as baked, with a note.

    Gathered bounce terms (:func:`gathered_terms`) bring their exact ``direct_one`` (S1, V)
    and fit ``observations``: then only the glossy anchors are smoothed (the gathered terms
    are not noise-bound: measured on the demo room, smoothing them over 1 / 2 spacings left
    the error at 0.0205 / raised it to 0.0224), with :data:`GATHER_PATCHES` patches."""
    from ..base.direct_rays import ReceiverRays

    try:
        rays = ReceiverRays(scene, tensors.objects, tensors.metadata.get("domain", "POINT"))
    except (ValueError, KeyError) as exc:
        tensors.metadata["bounce_transfer"] = {"two_bounce": "blended", "smoothing_spacings": 0,
                                               "skipped": str(exc)}
        tensors.metadata["notes"] = list(tensors.metadata.get("notes", [])) + [
            f"bounce terms not smoothed, second bounce blended: {exc}"]
        return tensors
    positions, normals = rays.receiver_frames()
    d1 = tensors.direction_sets()[1].directions
    if direct_one is not None:
        S1, S2 = len(tensors.one), len(tensors.two)
        per = min(GATHER_PATCHES, S1 // 2) if bounce_transfer.composes(S1, S2) else 0
        yield Progress(of or 1, of or 1, "fitting the second bounce")
        return ptt.with_bounce_transfer(tensors, positions, normals, direct_one, smoothing,
                                        per_region=per, smooth_bounces=False,
                                        observations=observations,
                                        two_weight=GATHER_TWO_WEIGHT)
    direct_one = np.zeros((len(d1), tensors.vertices), np.float32)
    if bounce_transfer.composes(len(tensors.one), len(tensors.two)):   # else only smoothing
        for s, w in enumerate(d1):
            direct_one[s] = rays.direct(w)
            yield Progress(of or s + 1, of or len(d1), "fitting the second bounce: direct "
                           f"light by rays, direction {s + 1} of {len(d1)}")
    yield Progress(of or len(d1), of or len(d1),
                   "smoothing the bounce terms, fitting the second bounce")
    return ptt.with_bounce_transfer(tensors, positions, normals, direct_one, smoothing)


def element_count(obj, domain: str) -> int:
    """Values a per-vertex bake of ``obj`` holds: vertices (POINT) or face corners (CORNER)."""
    return len(obj.data.loops) if domain == "CORNER" else len(obj.data.vertices)


def truth_irradiance(scene, objects, colours: dict, direction, bounces: int, samples: int,
                     seed: int = 1, angle_deg: float = 0.0, domain: str = "POINT",
                     finish: dict | None = None) -> np.ndarray:
    """Cycles ground truth of an edit: irradiance E (V, 3) (per unit normal irradiance) of the
    stacked vertices of ``objects`` under a Sun from ``direction``, with every material a
    Diffuse BSDF of its colour (``colours[name]`` where given, else its own) and ``bounces``
    bounces -- the same diffuse scene the tensors model, without any gating. ``finish``
    ``{name: (metallic, roughness)}`` mixes in a Principled metal of the material's colour
    (Principled with metallic ``m`` and no dielectric specular), glossy bounces included."""
    finish = {k: v for k, v in (finish or {}).items() if float(v[0]) > 0}
    with GatedMaterials(scene, [], colours, gloss=bool(finish)) as gates:
        gates.set_gates("all", "all")
        gates.set_finish(finish)
        with EnvironmentBake(scene, list(objects), None, samples, bounces, (8, 16),
                             mode="irradiance", seed=seed, world_sampling="none",
                             domain=domain, glossy_bounces=bounces if finish else 0) as session:
            values = session.bake_sun_all(direction, 1.0, angle_deg)
    return np.pi * np.concatenate(values, axis=0)


@dataclass
class MaterialsBakeOutput:
    """A ``bake-materials`` run: its JSON-safe report and the tensors."""
    report: dict
    tensors: ptt.TransferTensors


def tensors_path(out_dir: str, objects) -> str:
    safe = object_stem(objects[0].name)
    return os.path.join(out_dir, safe + "_materials.npz")


def report_path(out_dir: str, objects) -> str:
    return tensors_path(out_dir, objects)[:-4] + ".json"


def reference_sun(scene):
    """Direction (towards it), angular diameter (degrees) and strength of the scene's Sun lamp
    (a rendered one first; the sample scenes keep theirs hidden for the preview to follow),
    or None."""
    from mathutils import Vector

    suns = [o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"]
    suns.sort(key=lambda o: o.hide_render)
    for o in suns:
        d = (o.matrix_world.to_quaternion() @ Vector((0.0, 0.0, 1.0))).normalized()
        return np.array(d[:]), float(np.degrees(o.data.angle)), float(o.data.energy)
    return None


def load_tensors(scene, obj) -> ptt.TransferTensors:
    """The material bake recorded on ``obj`` (its first object); ValueError / FileNotFoundError
    say which command fixes it."""
    from ..base.blend_files import bake_file

    return ptt.TransferTensors.load(bake_file(obj, KIND, "material (bake-materials)"))


def file_colours(tensors: ptt.TransferTensors) -> dict:
    """The editable regions' colours as the open file has them now (the edit-free state)."""
    out = {}
    for i, name in enumerate(tensors.regions):
        mat = bpy.data.materials.get(name)
        out[name] = (tuple(material_colour(mat)[0]) if mat is not None
                     else tuple(tensors.base_colors[i]))
    return out


def file_finish(tensors: ptt.TransferTensors) -> dict:
    """The editable regions' (metallic, roughness) as the open file has them now; {} for a bake
    without glossy anchors (its regions are diffuse whatever the file says)."""
    if not tensors.roughness:
        return {}
    out = {}
    for i, name in enumerate(tensors.regions):
        mat = bpy.data.materials.get(name)
        out[name] = (material_finish(mat) if mat is not None
                     else tuple(tensors.base_finish[i]))
    return out


def ground_truth(scene, objects, tensors: ptt.TransferTensors, direction, samples: int) -> dict:
    """Relative error of the tensors against a Cycles bake of the file's colours under a hard
    sun from ``direction``, next to the noise floor (two truth seeds), and without the
    two-bounce term; errors are ``||E - E_cycles|| / ||E_cycles||`` over vertices and RGB."""
    colours, finish = file_colours(tensors), file_finish(tensors)
    t = time.perf_counter()
    domain = tensors.metadata.get("domain", "POINT")
    a = truth_irradiance(scene, objects, colours, direction, tensors.bounces, samples, seed=1,
                         domain=domain, finish=finish)
    b = truth_irradiance(scene, objects, colours, direction, tensors.bounces, samples, seed=2,
                         domain=domain, finish=finish)
    seconds = time.perf_counter() - t
    from ..base.direct_rays import exact_direct

    light = ptt.Sun(tuple(float(v) for v in direction))
    exact = exact_direct(scene, tensors, light)
    est = tensors.irradiance(light, colours, direct=exact, finish=finish)
    low = tensors.irradiance(light, colours, orders=(0, 1), direct=exact, finish=finish)

    def rel(x, y):
        return float(np.linalg.norm(x - y) / max(np.linalg.norm(y), 1e-30))

    return {"samples": samples, "light": [round(float(v), 5) for v in direction],
            "rel_error": rel(est, a), "noise_floor": rel(b, a),
            "rel_error_without_two_bounce": rel(low, a),
            "rel_error_baked_direct": rel(tensors.irradiance(light, colours, finish=finish), a),
            "direct": "rays" if exact is not None else "baked",
            "truth_seconds": round(seconds, 3)}


def materials_job(scene, objects, settings: MaterialBakeSettings, out_dir: str,
                  truth_samples: int = 0, resume: bool = True, client=None,
                  blend_path: str | None = None):
    """The ``bake-materials`` verb as one job: bake, then write ``<object>_materials.npz`` and
    its JSON report (bake count, seconds, bytes, each path order's share of the light under
    the scene's Sun, or a 45-degree sun; with ``truth_samples`` the error against Cycles
    there) and record the file on the first object. Nothing but the chunk cache is written if
    it is cancelled: with ``resume`` the finished chunks are kept in
    ``<out_dir>/.relight_cache`` until the files are written, so a rerun redoes only the
    missing ones; a Dask ``client`` bakes them on its workers from ``blend_path``."""
    from ..base.blend_files import record_kind

    started = time.perf_counter()
    settings.validate()
    cache = material_chunk_cache(scene, objects, settings, out_dir) if resume else None
    tensors = yield from bake_materials(scene, objects, settings, cache, client, blend_path)
    chunks = tensors.metadata.pop("chunks")   # the run's figures: the report, not the file
    sun = reference_sun(scene)
    direction = (sun[0] if sun is not None and sun[0][2] > 0
                 else np.array([0.5, 0.5, np.sqrt(0.5)]))
    light = ptt.Sun(tuple(float(v) for v in direction))
    shares = tensors.term_shares(light, file_colours(tensors), finish=file_finish(tensors))
    d0, d1, d2 = tensors.direction_sets()
    report = {"objects": [o.name for o in objects], "vertices": tensors.vertices,
              "domain": settings.domain,
              "regions": tensors.regions, "anchors": settings.anchors,
              "finish": {k: [round(float(x), 4) for x in v]
                         for k, v in file_finish(tensors).items()},
              "bounces": settings.bounces,
              "samples": settings.samples if not settings.gathers else None,
              "rays": settings.rays if settings.gathers else None, "seed": settings.seed,
              "anchor_samples": settings.anchor_samples if settings.roughness else None,
              "anchor_directions": settings.anchor_spec() if settings.roughness else None,
              "directions": {"direct": d0.spec, "one_bounce": d1.spec, "two_bounce": d2.spec},
              "bake_calls": tensors.metadata["bake_calls"],
              "direct": tensors.metadata.get("direct"),
              "bounce_bake": settings.bounce_bake,
              "device": cycles_device.current().report(),
              "bytes": {"tensors": tensors.nbytes},
              "energy_shares": {k: round(v, 5) for k, v in shares.items()},
              "energy_light": {"direction": [round(float(v), 5) for v in direction],
                               "from": "scene Sun" if sun is not None else "45-degree sun"},
              "notes": tensors.metadata["notes"],
              "bounce_transfer": tensors.metadata.get("bounce_transfer", {}),
              **({"gather": tensors.metadata["gather"]} if "gather" in tensors.metadata
                 else {}),
              "timings": {"bake_seconds": tensors.metadata["bake_seconds"],
                          "cycles_seconds": tensors.metadata["cycles_seconds"],
                          **{f"{k}_seconds": v for k, v in tensors.metadata["seconds"].items()}}}
    if truth_samples:
        yield Progress(0, 1, f"Cycles truths ({truth_samples} spp, 2 seeds)")
        report["ground_truth"] = ground_truth(scene, objects, tensors, direction, truth_samples)
    os.makedirs(out_dir, exist_ok=True)
    path = tensors_path(out_dir, objects)
    tensors.save(path)
    record_kind(objects[0], KIND, path, {"regions": list(tensors.regions),
                                         "objects": [o.name for o in objects],
                                         "anchors": settings.anchors})
    report["tensors"] = path
    report["bytes"]["file"] = os.path.getsize(path)
    report.update(chunks)
    if cache is not None:   # once the bake is committed the chunks have served
        after_commit(out_dir, cache.clear)
    report["timings"]["wall_total"] = round(time.perf_counter() - started, 4)
    report["warnings"] = report_warnings(report)   # its notes and checks, as the CLI says them
    atomic.write_json(report_path(out_dir, objects), {**report, "format_version": REPORT_VERSION})
    return MaterialsBakeOutput(report, tensors)
