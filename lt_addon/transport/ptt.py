"""Precomputed transfer tensors per vertex for diffuse material edits (Sun et al. 2007), bpy-free.

The light a surface throws onto the rest of the scene depends on that surface's material, so
ordinary precomputed transport freezes the materials. Sun et al. split the light arriving at a
receiver by path: direct, one bounce off region ``r``, two bounces off the ordered pair
``r1 -> r2``. For diffuse regions whose albedo ``c_r`` (RGB) is edited, the receiver's
irradiance is a polynomial in the albedos:

    E(v) = D(v) . L  +  sum_r c_r * O_r(v) . L  +  sum_{r1, r2} c_r1 * c_r2 * W_{r1 r2}(v) . L

where ``. L`` contracts a term's light directions with the lighting's weights (a sun:
interpolation weights over the baked directions times its normal irradiance; an environment:
``L(w_s) dw_s``), ``*`` is per colour channel, and:

* ``D`` (S0, V): direct irradiance per unit normal irradiance from direction ``s``
  (visibility x cosine), single channel;
* ``O`` (S1, 3, R+1, V): irradiance at ``v`` from light that reflected once off region ``r``,
  per colour channel;
* ``W`` (S2, 3, R+1, R+1, V): irradiance from light that reflected off ``r1`` and then ``r2``.

Direction-major storage on purpose: a sun touches a few directions, i.e. a few contiguous
blocks (measured at 13K vertices: 1 ms for three blocks where gathering the same columns
from a vertex-major array took 4-6 ms), an environment is one matrix product per channel, and
a bake writes one block per Cycles call.

Region 0 holds every surface that is not editable, at its own colour (its coefficient is 1);
regions 1..R are the editable materials, baked with albedo 1 (their coefficient is the current
albedo). Coarser direction sets serve the higher orders: indirect light changes slowly with
the light direction (the paper: a 6x8x8 cube map for one bounce, 6x2x2 for two).

Run time: a lighting change contracts every term with the new weights (:meth:`project`, about
``V (S0' + 3 (R+1) S1 + 3 (R+1)^2 S2)`` multiply-adds; ``S0'`` is the few directions a sun's
kernel touches); a material change only recombines the contracted terms (:meth:`combine`,
``3 V (R+1)^2``). Outgoing radiance of a diffuse receiver is ``albedo(v) / pi * E(v)``.

Since version 2 a bake may carry a :class:`.bounce_transfer.BounceTransfer` (``bounce``): the
bounce terms were smoothed over the surface at bake time, and :meth:`project` composes the
two-bounce light from the projected one-bounce light instead of blending the coarse ``W``
(see that module for why and what it measured).

Since version 3 a bake may carry *glossy anchors* (``gloss``): per editable region and
roughness anchor ``rho_k``, the one-bounce light off the region as a white GGX metal of roughness
``rho_k`` (Principled, metallic 1). Cycles cannot shade negative BRDFs, so these non-negative
anchors stand in for the paper's BRDF basis; transport is linear in the BRDF, so a region with
Principled colour ``c``, metallic ``m`` and roughness ``rho`` (specular IOR level 0: the
dielectric's specular layer is not modelled) reflects

    (1 - m) c * diffuse  +  m c * sum_k w_k(rho) * metal(rho_k)

with ``w`` the linear interpolation weights of ``rho`` between the anchors (clamped to their
range). ``m c`` for a coloured metal drops Schlick's grazing term ``(1 - c)(1 - mu)^5``. The
second bounce of a glossy region's light is composed like the diffuse one (it needs the
:class:`.bounce_transfer.BounceTransfer`); a metal as the *second* surface of a path is taken
as diffuse with its colour (:meth:`TransferTensors.combine`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ..io import atomic
from ..sphere.directions import DirectionSet
from .bounce_transfer import BounceTransfer
from .gathered_transfer import ReceiverTransfer
from .texture import environment_weights, parse_directions, sun_weights
from ..io.npz import save_npz

FORMAT = "relight-transfer-tensors"
VERSION = 4
#: Versions :meth:`TransferTensors.load` reads (1: no bounce transfer; 2: no glossy anchors;
#: 3: glossy anchors at the one-bounce directions; 4: at their own, ``gloss_spec``).
READS = (1, 2, 3, 4)
#: At most this many roughness anchors per region (each costs S1 bakes per region).
MAX_ANCHORS = 4


def parse_anchors(spec: str) -> tuple:
    """``"diffuse"`` -> () (colour edits only); ``"roughness:0.2,0.5,0.9"`` -> the sorted
    roughness values (0..1) of the glossy anchors baked besides the diffuse one. ValueError
    with the reason otherwise."""
    spec = str(spec).strip()
    if spec == "diffuse":
        return ()
    kind, sep, values = spec.partition(":")
    if kind != "roughness" or not sep:
        raise ValueError(f"anchors must be 'diffuse' or 'roughness:R1,R2,...', got {spec!r}")
    try:
        rho = sorted(float(v) for v in values.split(","))
    except ValueError:
        raise ValueError(f"roughness anchors must be numbers, got {values!r}") from None
    if not rho or len(rho) > MAX_ANCHORS:
        raise ValueError(f"give 1..{MAX_ANCHORS} roughness anchors, got {len(rho)}")
    if (not np.all(np.isfinite(rho)) or rho[0] < 0.05 or rho[-1] > 1.0
            or len(set(rho)) != len(rho)):
        raise ValueError(f"roughness anchors must be distinct values in 0.05..1 (below 0.05 "
                         f"a metal is a mirror the bake's noise cannot resolve), got {values!r}")
    return tuple(rho)


def anchor_weights(anchors: tuple, metallic, roughness) -> np.ndarray:
    """Weights (R, K) float64 of the K glossy ``anchors`` for regions with ``metallic`` (R,)
    and ``roughness`` (R,): ``m * w_k(rho)``, ``w`` the linear interpolation weights of
    ``rho`` between the anchors (clamped to their range; one anchor: 1)."""
    m = np.clip(np.asarray(metallic, np.float64), 0.0, 1.0)
    rho = np.asarray(roughness, np.float64)
    K = len(anchors)
    eye = np.eye(K)
    w = (np.stack([np.interp(rho, anchors, eye[k]) for k in range(K)], axis=1)
         if K else np.zeros((len(m), 0)))
    return m[:, None] * w


@dataclass(frozen=True)
class Sun:
    """A distant sun: ``direction`` (3,) towards it (world, z up), angular diameter in degrees,
    normal irradiance ``strength`` (W/m^2) and linear RGB ``color``."""

    direction: tuple
    angle_deg: float = 0.0
    strength: float = 1.0
    color: tuple = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class Environment:
    """An equirectangular radiance image (H, W[, 3]) in W/m^2/sr, ``row_order`` "top_first" or
    "bottom_first", rotated about +z by ``rotation_deg`` (see ``texture.environment_weights``)."""

    image: np.ndarray
    row_order: str = "top_first"
    rotation_deg: float = 0.0
    strength: float = 1.0


def light_weights(dset: DirectionSet, light, sparse_weights: tuple | None = None) -> np.ndarray:
    """Dense weights (S, 3) float64 of ``light`` over the baked directions ``dset``: a term
    ``T`` (V, S[, 3]) times these, summed over S, is the irradiance in W/m^2 (a sun's
    ``sparse_weights``, :func:`.texture.sun_weights` of it, when the caller has them)."""
    S = dset.size
    w = np.zeros((S, 3))
    if isinstance(light, Sun):
        idx, k = sparse_weights or sun_weights(dset, light.direction, light.angle_deg)
        w[idx] = (k * float(light.strength))[:, None] * np.asarray(light.color, float)[None, :]
        return w
    if isinstance(light, Environment):
        e = environment_weights(dset, light.image, row_order=light.row_order,
                                rotation_deg=light.rotation_deg) * float(light.strength)
        return e if e.ndim == 2 and e.shape[1] == 3 else np.repeat(
            np.asarray(e).reshape(S, -1)[:, :1], 3, axis=1)
    raise TypeError(f"light must be a Sun or an Environment, got {type(light).__name__}")


@dataclass
class ComposedBounce:
    """The composed second bounce of one lighting before it is spread over the receivers
    (:class:`.bounce_transfer.BounceTransfer`): ``light`` (3, R+1, K) float32, the patches'
    reflected one-bounce light per source region; ``rest`` (3, P, V) float32 the blended
    baked term of the ``rest_pairs`` (P, 2) the composition does not cover (a flat wall's
    own); with glossy anchors ``gloss_light`` (3, R*K_a, K) and ``gloss_scale`` (R*K_a, R+1)."""

    bounce: BounceTransfer
    light: np.ndarray
    rest_pairs: np.ndarray
    rest: np.ndarray
    gloss_light: np.ndarray | None = None
    gloss_scale: np.ndarray | None = None


@dataclass
class ProjectedLight:
    """The terms contracted with one lighting, channel first: direct (3, V), one (3, R+1, V),
    float32 irradiance in W/m^2 (one may have zero regions); the second bounce either
    ``blended`` (3, R+1, R+1, V) (the baked term, or none: zero regions) or ``composed``
    (:class:`ComposedBounce`, spread over the receivers only when :attr:`two` is read:
    :meth:`TransferTensors.combine` weighs the patches first); with glossy anchors ``gloss``
    (3, R, K, V) (its composed second bounce: :attr:`gloss_two`; ``gloss_covers`` (R, R+1)
    bool: the pairs ``r -> r2`` it composes); ``fixed``: the receivers whose one-bounce light
    the receiver transfer made exact (:class:`.gathered_transfer.ReceiverTransfer`)."""

    direct: np.ndarray
    one: np.ndarray
    blended: np.ndarray | None = None
    composed: ComposedBounce | None = None
    gloss: np.ndarray | None = None
    gloss_covers: np.ndarray | None = None
    fixed: int = 0

    @property
    def has_two(self) -> bool:
        return self.composed is not None or (self.blended is not None and self.blended.size > 0)

    @property
    def two(self) -> np.ndarray:
        """(3, R+1, R+1, V) float32: the two-bounce light per ordered pair ``r1 -> r2``."""
        cb = self.composed
        if cb is None:
            return self.blended
        two = cb.bounce.spread(cb.light, cb.bounce.scale)
        if len(cb.rest_pairs):
            two[:, cb.rest_pairs[:, 0], cb.rest_pairs[:, 1]] = cb.rest
        return two

    @property
    def gloss_two(self) -> np.ndarray | None:
        """(3, R, K, R+1, V) float32: the glossy anchors' light reflected once more off each
        region (None without the composition)."""
        cb = self.composed
        if cb is None or cb.gloss_light is None:
            return None
        R, K = self.gloss.shape[1:3]
        V = self.direct.shape[-1]
        return cb.bounce.spread(cb.gloss_light, cb.gloss_scale).reshape(3, R, K, -1, V)


@dataclass
class TransferTensors:
    """Per-vertex transfer tensors of a set of objects (see the module docstring).

    Attributes
    ----------
    direct : (S0, V) float32
    one : (S1, 3, R+1, V) float32, or shape (0, 3, 0, V) without bounces
    two : (S2, 3, R+1, R+1, V) float32, or shape (0, 3, 0, 0, V) below 2 bounces
    specs : (str, str, str)
        Direction-set specs of the three orders (``texture.parse_directions``).
    regions : list of str
        The R editable material names (region ``i + 1``).
    base_colors : (R, 3) float64
        The editable materials' own colours in the file (the edit-free albedos).
    receiver_region : (V,) int16
        Region of each vertex's faces (0 = fixed).
    receiver_albedo : (V, 3) float32
        Each vertex's own diffuse colour in the file (used for fixed receivers).
    objects : list of (name, vertex count)
        The objects in the order their vertices are stacked.
    metadata : dict
        Bake settings, counts and timings (JSON).
    bounce : BounceTransfer or None
        The second-bounce composition (:mod:`.bounce_transfer`), None to blend ``two``.
    roughness : tuple of float
        The K glossy anchors' roughness values (module docstring), () for colour edits only.
    gloss : (Sg, R, K, V) float32 or None
        One-bounce irradiance off each editable region as a white metal at each anchor (one
        channel: the sun and the anchor are white), over the directions ``gloss_spec``.
    base_finish : (R, 2) float64 or None
        The editable materials' own (metallic, roughness) in the file.
    gloss_spec : str or None
        Direction set of ``gloss`` (None: the one-bounce set, ``specs[1]``, as version 3 had).
    receiver_transfer : ReceiverTransfer or None
        With gathered bounce terms: the transfer between the receivers that makes a sun's
        one-bounce light exact where its shadow edges lie between the baked directions
        (:meth:`project` with an exact ``direct``; :mod:`.gathered_transfer`).
    """

    direct: np.ndarray
    one: np.ndarray
    two: np.ndarray
    specs: tuple
    regions: list
    base_colors: np.ndarray
    receiver_region: np.ndarray
    receiver_albedo: np.ndarray
    objects: list
    metadata: dict = field(default_factory=dict)
    bounce: BounceTransfer | None = None
    roughness: tuple = ()
    gloss: np.ndarray | None = None
    base_finish: np.ndarray | None = None
    gloss_spec: str | None = None
    receiver_transfer: ReceiverTransfer | None = None

    def __post_init__(self):
        V = self.direct.shape[1]
        R1 = len(self.regions) + 1
        if (self.one.ndim != 4 or self.one.shape[1] != 3 or self.one.shape[2] not in (0, R1)
                or self.one.shape[3] != V):
            raise ValueError(f"one-bounce term has shape {self.one.shape}, expected "
                             f"(S1, 3, {R1}, {V})")
        if (self.two.ndim != 5 or self.two.shape[1] != 3
                or self.two.shape[2:4] not in ((0, 0), (R1, R1)) or self.two.shape[4] != V):
            raise ValueError(f"two-bounce term has shape {self.two.shape}, expected "
                             f"(S2, 3, {R1}, {R1}, {V})")
        if self.receiver_region.shape != (V,) or self.receiver_albedo.shape != (V, 3):
            raise ValueError("receiver arrays do not match the vertex count")
        if sum(n for _, n in self.objects) != V:
            raise ValueError("the objects' vertex counts do not add up to the terms' rows")
        b = self.bounce
        if b is not None and (b.transfer.shape != (len(b.patch_region), V)
                              or b.scale.shape != (R1, R1) or b.patch.shape != (V,)
                              or b.source_albedo.shape != (V, 3)
                              or (V and int(b.patch.max(initial=0)) >= len(b.patch_region))):
            raise ValueError("the bounce transfer does not match the terms")
        R, K = len(self.regions), len(self.roughness)
        if self.gloss_spec is None:
            self.gloss_spec = self.specs[1]
        self._gloss_dset = parse_directions(self.gloss_spec)
        Sg = self._gloss_dset.size
        if K and (self.gloss is None or self.gloss.shape != (Sg, R, K, V)
                  or not self.one.size):
            raise ValueError(f"glossy anchors need a gloss term of shape "
                             f"({Sg}, {R}, {K}, {V}) and one-bounce terms")
        if not K:
            self.gloss = None
        rt = self.receiver_transfer
        if rt is not None and (rt.matrix.shape != ((len(self.regions) + 1) * V, V)
                               or rt.direct_one.shape != (self.one.shape[0], V)
                               or rt.source_albedo.shape != (V, 3)):
            raise ValueError("the receiver transfer does not match the terms")
        if self.base_finish is None:
            self.base_finish = np.tile([0.0, 0.5], (R, 1))
        self.base_finish = np.asarray(self.base_finish, np.float64).reshape(R, 2)
        self._dsets = [parse_directions(s) for s in self.specs]
        for k, term in enumerate((self.direct, self.one, self.two)):
            if term.size and term.shape[0] != self._dsets[k].size:
                raise ValueError(f"term {k} has {term.shape[0]} directions, its set "
                                 f"{self.specs[k]!r} {self._dsets[k].size}")

    # -- sizes -------------------------------------------------------------------------------
    @property
    def vertices(self) -> int:
        return int(self.direct.shape[1])

    @property
    def bounces(self) -> int:
        return 2 if self.two.size else (1 if self.one.size else 0)

    @property
    def nbytes(self) -> int:
        extra = self.bounce.nbytes if self.bounce is not None else 0
        extra += self.gloss.nbytes if self.gloss is not None else 0
        extra += self.receiver_transfer.nbytes if self.receiver_transfer is not None else 0
        return int(self.direct.nbytes + self.one.nbytes + self.two.nbytes + extra)

    def direction_sets(self) -> list:
        return list(self._dsets)

    # -- albedos -----------------------------------------------------------------------------
    def albedos(self, edits: dict | None = None) -> np.ndarray:
        """Region coefficients (R+1, 3): 1 for the fixed region, then each editable region's
        colour: ``edits[name]`` (RGB, >= 0) where given, else the file's own colour."""
        edits = dict(edits or {})
        unknown = sorted(set(edits) - set(self.regions))
        if unknown:
            raise KeyError(f"not an editable region: {', '.join(unknown)} (editable: "
                           f"{', '.join(self.regions) or 'none'})")
        c = np.ones((len(self.regions) + 1, 3))
        for i, name in enumerate(self.regions):
            rgb = np.asarray(edits.get(name, self.base_colors[i]), dtype=np.float64)
            if rgb.shape != (3,) or not np.all(np.isfinite(rgb)) or rgb.min() < 0:
                raise ValueError(f"colour of {name!r} must be three non-negative numbers")
            c[i + 1] = rgb
        return c

    def anchor_weights(self, finish: dict | None = None) -> np.ndarray:
        """Glossy anchor weights (R, K) (:func:`anchor_weights`) for ``finish``
        ``{region: (metallic, roughness)}`` (the file's own where not given). Without glossy
        anchors (K = 0) a metallic edit is a ValueError: the bake has no light for it."""
        finish = dict(finish or {})
        unknown = sorted(set(finish) - set(self.regions))
        if unknown:
            raise KeyError(f"not an editable region: {', '.join(unknown)}")
        mr = self.base_finish.copy()
        for i, name in enumerate(self.regions):
            if name in finish:
                m, rho = (float(v) for v in finish[name])
                if not (0.0 <= m <= 1.0 and 0.0 <= rho <= 1.0):
                    raise ValueError(f"metallic and roughness of {name!r} must be in 0..1")
                if m > 0 and not self.roughness:
                    raise ValueError(f"{name!r}: metallic {m:g} needs glossy anchors: bake "
                                     "with --anchors roughness:R1,R2,...")
                mr[i] = (m, rho)
        if not self.roughness:
            return np.zeros((len(self.regions), 0))
        return anchor_weights(self.roughness, mr[:, 0], mr[:, 1])

    # -- relighting --------------------------------------------------------------------------
    def project(self, light, direct=None, compose: bool = True,
                gloss: bool = True) -> ProjectedLight:
        """Contract every term with ``light`` (a :class:`Sun` or :class:`Environment`);
        ``gloss=False`` leaves the glossy anchors out (no region is metallic: half the
        update at 13K vertices).

        With a :attr:`bounce` transfer (and ``compose``) the two-bounce light is composed from
        the contracted one-bounce light (:meth:`.BounceTransfer.compose`); ``compose=False``
        blends the baked ``two`` as version 1 did.

        ``direct`` (V,): the direct term's visibility x cosine per unit normal irradiance for
        this sun, computed exactly elsewhere (a ray per receiver), instead of interpolating
        ``D`` between its baked directions; it is scaled by the sun's strength and colour.
        With a :attr:`receiver_transfer` it also makes the one-bounce light exact where the
        sun's shadow edges lie between the one-bounce directions."""
        V, R1 = self.vertices, len(self.regions) + 1
        if direct is not None:
            if not isinstance(light, Sun):
                raise TypeError("an exact direct term is a sun's: the environment's direct "
                                "light comes from D")
            direct = np.asarray(direct, dtype=np.float32)
            if direct.shape != (V,):
                raise ValueError(f"direct must have shape ({V},), got {direct.shape}")
        unit = direct   # per unit normal irradiance (V,), or None
        if direct is None:
            w0 = light_weights(self._dsets[0], light).astype(np.float32)
        sw1 = (sun_weights(self._dsets[1], light.direction, light.angle_deg)
               if isinstance(light, Sun) else None)
        w1 = light_weights(self._dsets[1], light, sw1).astype(np.float32)
        w2 = light_weights(self._dsets[2], light).astype(np.float32)

        def contract(term, w, rows):
            # term (S, 3, rows..., V) -> (3, rows..., V), over the directions the light touches
            out = np.zeros((3, int(np.prod(rows)) * V), np.float32)
            nz = np.nonzero(np.any(w != 0, axis=1))[0]
            if term.size and len(nz):
                block = term if len(nz) == len(w) else term[nz]
                for c in range(3):
                    out[c] = w[nz, c] @ block[:, c].reshape(len(nz), -1)
            return out.reshape((3, *rows, V))

        if direct is not None:
            rgb = np.float32(light.strength) * np.asarray(light.color, np.float32)
            direct = rgb[:, None] * direct[None, :]
        else:
            nz0 = np.nonzero(np.any(w0 != 0, axis=1))[0]
            direct = w0[nz0].T @ (self.direct if len(nz0) == len(w0) else self.direct[nz0])
        one = self._contract_one(w1) if self.one.size else contract(self.one, w1, (0,))
        fixed = 0
        if unit is not None and self.receiver_transfer is not None and self.one.size:
            idx, k = sw1
            if len(idx):
                _, fixed = self.receiver_transfer.one_bounce_fix(unit, idx, k, into=one,
                                                                 scale=rgb)
        composed = compose and self.bounce is not None and self.two.size and self.one.size
        blended = cb = None
        if composed:   # the composed pairs, and the others (a flat wall's own) blended
            rest = np.argwhere(~self.bounce.covers())                            # (P, 2)
            part = np.zeros((3, len(rest), V), np.float32)
            nz = np.nonzero(np.any(w2 != 0, axis=1))[0]
            if len(rest) and len(nz):   # index the pairs first: the whole term is 27x larger
                block = self.two[:, :, rest[:, 0], rest[:, 1]][nz]          # (k, 3, P, V)
                part = np.einsum("kc,kcpv->cpv", w2[nz], block)
            cb = ComposedBounce(self.bounce, self.bounce.patch_light(one), rest, part)
        else:
            blended = contract(self.two, w2, (R1, R1) if self.two.size else (0, 0))
        g_one = covers = None
        if self.gloss is not None and gloss:
            R, K = self.gloss.shape[1:3]
            wg = (w1 if self.gloss_spec == self.specs[1]
                  else light_weights(self._gloss_dset, light).astype(np.float32))
            nz = np.nonzero(np.any(wg != 0, axis=1))[0]
            g_one = np.zeros((3, R * K, V), np.float32)
            if len(nz):   # white anchors: one channel, the light's colour per channel
                g_one[:] = (wg[nz].T @ self.gloss[nz].reshape(len(nz), -1)).reshape(3, R * K, V)
            covers = np.zeros((R, R1), bool)
            if cb is not None:
                src = np.repeat(np.arange(1, R + 1), K)
                scale = self.bounce.source_scale(src)
                cb.gloss_light, cb.gloss_scale = self.bounce.patch_light(g_one), scale
                covers = scale.reshape(R, K, R1)[:, 0] != 0
            g_one = g_one.reshape(3, R, K, V)
        return ProjectedLight(np.ascontiguousarray(direct, np.float32), one, blended, cb, g_one,
                              covers, fixed)

    def _contract_one(self, w: np.ndarray) -> np.ndarray:
        """The one-bounce term contracted with weights ``w`` (S1, 3): (3, R+1, V) float32. A
        region whose three channels are one table (white light off an editable region; they
        are the same bits) is read once for all channels: an environment reads every
        direction, and at 13K vertices the term is 60 MB, most of an update's time."""
        if not hasattr(self, "_grey_one"):
            self._grey_one = [bool(np.array_equal(self.one[:, 0, r], self.one[:, 1, r])
                                   and np.array_equal(self.one[:, 0, r], self.one[:, 2, r]))
                              for r in range(self.one.shape[2])]
        V, R1 = self.vertices, self.one.shape[2]
        out = np.zeros((3, R1, V), np.float32)
        nz = np.nonzero(np.any(w != 0, axis=1))[0]
        if not len(nz):
            return out
        block = self.one if len(nz) == len(w) else self.one[nz]
        wt = np.ascontiguousarray(w[nz].T)                                    # (3, k)
        for r in range(R1):
            if self._grey_one[r]:
                out[:, r] = wt @ block[:, 0, r]
            else:
                for c in range(3):
                    out[c, r] = wt[c] @ block[:, c, r]
        return out

    def combine(self, projected: ProjectedLight, albedos: np.ndarray,
                orders: tuple = (0, 1, 2), anchors: np.ndarray | None = None) -> np.ndarray:
        """Irradiance E (V, 3) float32 (W/m^2) for region coefficients ``albedos`` (R+1, 3)
        (:meth:`albedos`) and glossy ``anchors`` weights (R, K) (:meth:`anchor_weights`; None:
        all diffuse); ``orders`` picks which path orders to sum (0 direct, 1, 2).

        A region of metallic ``m`` reflects ``(1 - m)`` of its colour diffusely: that scales
        its diffuse one-bounce term and the pairs it starts whose glossy second bounce is
        composed (``projected.gloss_covers``; a pair that is not, without the composition,
        keeps the diffuse term at the whole colour: its light as if the metal were diffuse),
        and ``m`` spreads over its glossy anchors. As the *second* surface of a pair it
        reflects its whole colour diffusely: the anchors hold no glossy second bounce, and
        taking it as diffuse came closer to Cycles than leaving it out (measured on the demo
        room, 7 held-out suns, anchors at 16 spp: both walls a white metal of roughness 0.5,
        0.083 against 0.090; the other metal edits equal or better)."""
        c = np.asarray(albedos, dtype=np.float32)
        cd, ca = self._coefficients(c, anchors)
        if ca is not None and projected.gloss is None:
            raise ValueError("a metallic region needs its glossy anchors projected "
                             "(project(..., gloss=True))")
        E = projected.direct.copy() if 0 in orders else np.zeros_like(projected.direct)
        if 1 in orders and projected.one.size:
            E += np.einsum("rc,crv->cv", cd, projected.one)
            if ca is not None:
                E += np.einsum("rkc,crkv->cv", ca, projected.gloss)
        if 2 in orders and projected.has_two:
            first = np.repeat(cd[:, None, :], len(c), axis=1)     # (R+1, R+1, 3)
            if ca is not None:   # pairs whose glossy light is not composed: as diffuse
                lost = ~projected.gloss_covers
                first[1:][lost] = np.repeat(c[1:, None, :], len(c), axis=1)[lost]
            pair = first * c[None, :, :]                          # (R+1, R+1, 3)
            cb = projected.composed
            if cb is None:
                E += np.einsum("abc,cabv->cv", pair, projected.blended)
            else:   # the patches weighed by the pairs' colours, then spread once
                E += cb.bounce.contract(cb.light, pair, cb.bounce.scale)
                if len(cb.rest_pairs):
                    E += np.einsum("pc,cpv->cv", pair[cb.rest_pairs[:, 0], cb.rest_pairs[:, 1]],
                                   cb.rest)
                if ca is not None and cb.gloss_light is not None:
                    coef = ca[:, :, None, :] * c[None, None, :, :]   # (R, K, R+1, 3)
                    E += cb.bounce.contract(cb.gloss_light, coef.reshape(-1, len(c), 3),
                                            cb.gloss_scale)
        return np.ascontiguousarray(E.T)

    def _coefficients(self, c: np.ndarray, anchors):
        """Diffuse coefficients (R+1, 3) and glossy ones (R, K, 3) (None without anchors or
        with every weight 0)."""
        if anchors is None or not np.any(anchors):
            return c, None
        a = np.asarray(anchors, np.float32)
        cd = c.copy()
        cd[1:] *= (1.0 - a.sum(axis=1))[:, None]
        return cd, c[1:, None, :] * a[:, :, None]

    def irradiance(self, light, edits: dict | None = None, orders=(0, 1, 2),
                   direct=None, finish: dict | None = None) -> np.ndarray:
        """E (V, 3) float32 in W/m^2 under ``light`` with the materials ``edits`` (colours)
        and ``finish`` (``{region: (metallic, roughness)}``; ``direct``: an exact direct term,
        see :meth:`project`)."""
        a = self.anchor_weights(finish)
        return self.combine(self.project(light, direct, gloss=bool(np.any(a))),
                            self.albedos(edits), orders, a)

    def receiver_colors(self, albedos: np.ndarray, anchors=None) -> np.ndarray:
        """Each vertex's own diffuse colour (V, 3) with the edited albedos applied (times
        ``1 - metallic`` with glossy ``anchors`` weights: a metal has no diffuse colour)."""
        cd, _ = self._coefficients(np.asarray(albedos, np.float32), anchors)
        col = self.receiver_albedo.astype(np.float32).copy()
        for r in range(1, len(self.regions) + 1):
            col[self.receiver_region == r] = cd[r]
        return col

    def shade(self, light, edits: dict | None = None, direct=None,
              finish: dict | None = None) -> np.ndarray:
        """Outgoing radiance (V, 3) float32 of the diffuse receivers: ``albedo / pi * E`` (a
        metal receiver's own glossy reflection is the renderer's)."""
        c, a = self.albedos(edits), self.anchor_weights(finish)
        return (self.receiver_colors(c, a) / np.float32(np.pi)
                * self.combine(self.project(light, direct, gloss=bool(np.any(a))), c,
                               anchors=a))

    def term_shares(self, light, edits: dict | None = None, direct=None,
                    finish: dict | None = None) -> dict:
        """Each path order's share of the summed irradiance (over vertices and RGB)."""
        c, a = self.albedos(edits), self.anchor_weights(finish)
        p = self.project(light, direct, gloss=bool(np.any(a)))
        parts = [float(self.combine(p, c, (k,), a).sum()) for k in (0, 1, 2)]
        total = sum(parts) or 1.0
        return {"direct": parts[0] / total, "one_bounce": parts[1] / total,
                "two_bounce": parts[2] / total}

    def object_slices(self) -> dict:
        """Row range of each object's vertices: ``{name: slice}``."""
        out, start = {}, 0
        for name, n in self.objects:
            out[name] = slice(start, start + n)
            start += n
        return out

    # -- files -------------------------------------------------------------------------------
    def save(self, path: str) -> None:
        """Write an .npz (float32 terms, JSON header) atomically."""
        # a file without glossy anchors stays version 2 (and 3 with them at the one-bounce
        # directions): older builds read it
        version = (2 if self.gloss is None else 3 if self.gloss_spec == self.specs[1]
                   else VERSION)
        header = {"format": FORMAT, "version": version, "specs": list(self.specs),
                  "gloss_spec": self.gloss_spec,
                  "regions": list(self.regions), "objects": [list(o) for o in self.objects],
                  "roughness": list(self.roughness), "metadata": self.metadata}
        extra = {"base_finish": self.base_finish}
        if self.gloss is not None:
            extra["gloss"] = self.gloss
        if self.bounce is not None:
            b = self.bounce
            extra.update({"patch": b.patch, "patch_region": b.patch_region, "transfer": b.transfer,
                     "source_albedo": b.source_albedo, "two_scale": b.scale})
        rt = self.receiver_transfer
        if rt is not None:   # optional arrays: builds without it read the file and blend
            m = rt.matrix
            extra.update({"fix_direct_one": rt.direct_one, "fix_source_albedo": rt.source_albedo,
                          "fix_data": m.data, "fix_indices": m.indices, "fix_indptr": m.indptr})
        with atomic.atomic_path(path) as tmp:
            save_npz(tmp, header=np.frombuffer(json.dumps(header).encode(), np.uint8),
                     direct=self.direct, one=self.one, two=self.two,
                     base_colors=self.base_colors, receiver_region=self.receiver_region,
                     receiver_albedo=self.receiver_albedo, **extra)

    @classmethod
    def load(cls, path: str) -> "TransferTensors":
        """Read a file written by :meth:`save` as a file from elsewhere (the material-edit
        handler reads it without asking): a capped NPZ (:func:`..io.untrusted.open_npz`), its
        header a JSON object; the receiver transfer's sparse index arrays checked before SciPy
        builds the matrix (:func:`..io.untrusted.sparse_matrix`: its C++ products index
        without bounds checks); region and patch indices in range; the terms' shapes by
        :meth:`__post_init__`. Anything wrong: one UntrustedFileError naming the file."""
        from ..io import untrusted as ut

        with ut.open_npz(path, stored=True) as z:
            header = ut.npz_json(z)
            if header.get("format") != FORMAT:
                raise ut.UntrustedFileError(path, "is not a transfer-tensor file")
            if header.get("version") not in READS:
                raise ut.UntrustedFileError(
                    path, f"has version {header.get('version')!r:.20}; this build reads "
                          f"versions {', '.join(map(str, READS))}: bake the materials again")
            regions = ut.field(header, "regions", path, list)
            specs = ut.field(header, "specs", path, list)
            objects = ut.field(header, "objects", path, list)
            R1 = len(regions) + 1
            try:
                direct = z.get("direct", shape=(None, None), dtype="f")
                V = direct.shape[1]
                arrays = {k: z.get(k, dtype="fiu") for k in (
                    "one", "two", "base_colors", "receiver_region", "receiver_albedo")}
                for k in ("direct", "one", "two", "base_colors", "receiver_albedo"):
                    ut.check_values(path, direct if k == "direct" else arrays[k], what=k)
                reg = arrays["receiver_region"]
                if reg.size and (int(reg.min()) < 0 or int(reg.max()) > len(regions)):
                    raise ut.UntrustedFileError(path, "has receiver regions outside "
                                                      f"0..{len(regions)}")
                bounce = None
                if "transfer" in z:
                    patch = z.get("patch", shape=(V,), dtype="iu")
                    preg = z.get("patch_region", shape=(None,), dtype="iu")
                    if patch.size and (int(patch.min()) < 0 or int(patch.max()) >= len(preg)):
                        raise ut.UntrustedFileError(path, "has patch indices out of range")
                    if preg.size and (int(preg.min()) < 0 or int(preg.max()) > len(regions)):
                        raise ut.UntrustedFileError(path, "has patch regions out of range")
                    bounce = BounceTransfer(patch, preg, z.get("transfer", dtype="f"),
                                            z.get("source_albedo", dtype="f"),
                                            z.get("two_scale", dtype="f"))
                fix = None
                if "fix_direct_one" in z:
                    fix = ReceiverTransfer(
                        ut.sparse_matrix(path, "csc", z.get("fix_data", dtype="f"),
                                         z.get("fix_indices", dtype="iu"),
                                         z.get("fix_indptr", dtype="iu"), (R1 * V, V)),
                        z.get("fix_direct_one", dtype="f"),
                        z.get("fix_source_albedo", dtype="f"))
                return cls(direct, arrays["one"], arrays["two"], tuple(specs), list(regions),
                           arrays["base_colors"], reg, arrays["receiver_albedo"],
                           [tuple(o) for o in objects], header.get("metadata", {}), bounce,
                           tuple(header.get("roughness", ())),
                           z.get("gloss", dtype="f") if "gloss" in z else None,
                           z.get("base_finish", dtype="f") if "base_finish" in z else None,
                           header.get("gloss_spec"), fix)
            except ut.UntrustedFileError:
                raise
            except (ValueError, TypeError, IndexError, KeyError) as exc:
                raise ut.UntrustedFileError(path, f"does not hold consistent terms "
                                                  f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None


def bake_count(s0: int, s1: int, s2: int, regions: int, bounces: int, anchors: int = 0,
               gloss_directions: int | None = None, rays: bool = False) -> int:
    """Cycles calls of a bake: ``S0 + S1 (R+1) + Sg R K + S2 ((R+1) + (R+1)^2)`` (the
    two-bounce terms need one reference bake per ``r2`` to subtract the one-bounce light; K
    glossy ``anchors`` per editable region add one-bounce bakes only, over ``gloss_directions``
    ``Sg``, default ``S1``). With the bounce terms gathered by ``rays``
    (:mod:`.gathered_transfer`) only ``S0 + Sg R K`` are Cycles calls."""
    r1 = regions + 1
    sg = s1 if gloss_directions is None else gloss_directions
    if bounces < 1:
        return s0
    if rays:
        return s0 + sg * regions * anchors
    return (s0 + s1 * r1 + sg * regions * anchors
            + (s2 * (r1 + r1 * r1) if bounces >= 2 else 0))


def with_bounce_transfer(tensors: TransferTensors, positions: np.ndarray, normals: np.ndarray,
                         direct_one: np.ndarray, spacings: float | None = None,
                         per_region: int | None = None, smooth_bounces: bool = True,
                         observations: tuple | None = None,
                         two_weight: float | None = None) -> TransferTensors:
    """The tensors with their bounce terms smoothed over the surface and a second-bounce
    composition fitted (:mod:`.bounce_transfer`; ``tensors`` is not changed).

    positions (V, 3) metres and normals (V, 3) of the receivers; direct_one (S1, V) the exact
    direct term (visibility x cosine) at the one-bounce directions. ``spacings`` (default
    ``SMOOTH_SPACINGS``; 0: no smoothing) and ``per_region`` patches (default
    :func:`.bounce_transfer.composes`: none, i.e. only the smoothing, when the one-bounce
    directions are too few to fit or no finer than the two-bounce ones).
    ``smooth_bounces=False`` smooths only the glossy anchors (the diffuse bounce terms were
    gathered by rays, :mod:`.gathered_transfer`: smoothing them only blurred them, measured).
    ``observations`` ``(one_at (S, 3, R+1, V), two (S, 3, R+1, R+1, V))``: the one- and
    two-bounce light at some directions the fit and calibration use instead of the stored
    two-bounce term and the one-bounce term blended at its directions (gathered terms: exact
    at any direction, so a finer set than the stored one), weighted ``two_weight`` in the fit
    (default :data:`.bounce_transfer.TWO_WEIGHT`, chosen for noisy Cycles-baked terms).
    ``metadata["bounce_transfer"]`` says what was done: the smoothing radius, the share of each
    region's one- and two-bounce energy the fit explains, the calibration scales and the pairs
    left blended."""
    from dataclasses import replace

    from . import bounce_transfer as bt

    spacings = bt.SMOOTH_SPACINGS if spacings is None else float(spacings)
    V, R1 = tensors.vertices, len(tensors.regions) + 1
    if per_region is None:
        per_region = bt.composes(tensors.one.shape[0], tensors.two.shape[0])
    op, radius = bt.smoothing_operator(positions, normals, spacings)
    if smooth_bounces:
        one, two = bt.smooth(op, tensors.one), bt.smooth(op, tensors.two)
    else:
        one, two = tensors.one, tensors.two
    gloss = bt.smooth(op, tensors.gloss) if tensors.gloss is not None else None
    info = {"smoothing_spacings": spacings, "smoothing_radius_m": round(radius, 6),
            "smoothed": "bounce terms" + (" and glossy anchors" if gloss is not None else "")
            if smooth_bounces else ("glossy anchors" if gloss is not None else "nothing")}
    out = replace(tensors, one=one, two=two, gloss=gloss, metadata=dict(tensors.metadata),
                  bounce=None)
    if two.size and one.size and per_region > 0:
        region = tensors.receiver_region.astype(np.int64)
        albedo = np.ones((V, 3), np.float32)
        albedo[region == 0] = tensors.receiver_albedo[region == 0]
        patch, owner = bt.region_patches(positions, normals, region, R1, per_region)
        if observations is None:
            one_at = np.stack([out.project(Sun(tuple(w)), compose=False, gloss=False).one
                               for w in out.direction_sets()[2].directions])
            two_obs = two
        else:
            one_at, two_obs = (np.asarray(x, np.float32) for x in observations)
        T, explained, explained_two = bt.fit_transfer(
            one, np.asarray(direct_one, np.float64), patch, owner, albedo, two=two_obs,
            one_at=one_at, two_weight=two_weight)
        transfer = bt.BounceTransfer(patch, owner, T, albedo, np.ones((R1, R1)))
        scale = bt.calibrate(transfer, one_at, two_obs)
        for r, e in explained.items():      # the patch model does not hold for this region
            if e < bt.MIN_EXPLAINED:
                scale[:, r] = 0.0
        transfer.scale = scale
        composed = bool(np.any(scale))
        out.bounce = transfer if composed else None
        info.update({"patches": int(len(owner)), "patches_per_region": per_region,
                     "fit_explained": {str(k): round(v, 4) for k, v in explained.items()},
                     "fit_explained_two": {str(k): round(v, 4)
                                           for k, v in explained_two.items()},
                     "two_bounce_scale": np.round(scale, 4).tolist(),
                     "two_bounce": "composed" if composed else "blended (the patch fit did "
                                                                "not hold)",
                     # pairs left to the baked term: nothing to compose (a flat wall does not
                     # light itself), no patches, or a calibration out of range
                     "blended_pairs": np.argwhere(scale == 0).tolist()})
    else:
        info["two_bounce"] = "blended" if two.size else "none"
    out.metadata["bounce_transfer"] = info
    return out
