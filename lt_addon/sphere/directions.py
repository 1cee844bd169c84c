"""Sets of sample directions on the sphere, each with the solid angle it stands for.

Per-vertex transport ``T[v, j]`` (Nowrouzezahrai et al. 2008, eq. 1) is sampled at a fixed set
of world-frame directions ``w_j``; every integral over the sphere becomes the quadrature
``sum_j f(w_j) dw_j`` with the per-sample solid angles ``dw_j`` (sr) returned here. The paper
uses Halton, latitude/longitude and cubemap sets (sec. 3, 5); all are built here, plus a
Gauss-Legendre cube quadrature that integrates smooth functions to machine precision (used to
check spherical-harmonic orthonormality).

Kinds and their sample order (index ``j``):

``halton`` -- :func:`halton_sphere`
    Point ``i = 1..n`` of the Halton sequence (radical inverses in bases 2 and 3) mapped
    area-uniformly: ``z = 1 - 2 h2(i)``, ``phi = 2 pi h3(i)``. Weights ``4 pi / n``. Not a
    lattice: interpolation uses the triangulated convex hull (:func:`interpolate_samples`).
``latlong`` -- :func:`latlong`
    Cell centres of an equirectangular grid of ``rows x cols`` cells in the Blender/Cycles
    convention of :mod:`.hemisphere` (``u = 0.5 - atan2(y, x) / 2 pi``,
    ``v = 0.5 + elevation / pi``). ``j = row * cols + col`` with **row 0 at the top** (zenith
    side, ``v`` near 1), i.e. the ``"top_first"`` order of an image. Exact cell solid angles
    ``(2 pi / cols) (sin el_top - sin el_bottom)``.
``cube`` -- :func:`cubemap`
    Texel centres of six ``n x n`` faces in the OpenGL cubemap convention (faces +X, -X, +Y,
    -Y, +Z, -Z; on each face ``d = major + s * s_axis + t * t_axis`` with ``s, t`` in
    ``[-1, 1]``, see :data:`CUBE_FACES`). ``j = face * n * n + row * n + col`` with texel
    ``(row, col)`` covering ``t`` in row ``row`` and ``s`` in column ``col``. Exact texel solid
    angles from ``A(s, t) = atan2(s t, sqrt(s^2 + t^2 + 1))``. Z is up (Blender world).
``cubegauss`` -- :func:`cube_gauss`
    ``n x n`` Gauss-Legendre nodes per face with weights ``w_a w_b / (1 + s^2 + t^2)^{3/2}``.
``hemi`` -- :func:`hemisphere_fibonacci`
    ``n`` directions over the *upper* hemisphere only (a distant light below the horizon is
    off): a Fibonacci spiral, ``z = u_i^p`` with ``u_i = (i + 0.5) / n`` and azimuth ``i`` times
    the golden angle. ``p = 1`` is uniform in solid angle; ``p > 1`` puts more directions near
    the horizon, where grazing shadows change fastest. Weights ``2 pi p u_i^(p-1) / n`` (sum
    2 pi). Spec ``hemi:N`` or ``hemi:N:P``.

A :class:`DirectionSet` is described by a short *spec* string (``"halton:1024"``,
``"latlong:32x64"``, ``"cube:16"``, ``"cubegauss:12"``; :func:`parse_direction_spec`) that is
stored in sidecar metadata so the exact set can be rebuilt.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.spatial

from ..errors import InputError
from ..io import untrusted as _untrusted
from .hemisphere import direction_to_equirect_uv, equirect_uv_to_direction, normalize_directions

KINDS = ("halton", "latlong", "cube", "cubegauss", "hemi")

#: Cubemap faces (OpenGL convention): (major axis, s axis, t axis); a texel direction is
#: ``major + s * s_axis + t * t_axis`` for ``s, t`` in [-1, 1].
CUBE_FACES = np.array([
    [[1, 0, 0], [0, 0, -1], [0, -1, 0]],   # +X
    [[-1, 0, 0], [0, 0, 1], [0, -1, 0]],   # -X
    [[0, 1, 0], [1, 0, 0], [0, 0, 1]],     # +Y
    [[0, -1, 0], [1, 0, 0], [0, 0, -1]],   # -Y
    [[0, 0, 1], [1, 0, 0], [0, -1, 0]],    # +Z
    [[0, 0, -1], [-1, 0, 0], [0, -1, 0]],  # -Z
], dtype=np.float64)
CUBE_FACE_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")

#: Largest number of directions a spec may ask for (a guard against typos like "halton:1e9",
#: and against a spec read from someone else's file sizing the allocations): the cap on
#: direction sets of :mod:`..io.untrusted` (65536; a production bake uses 400-1600).
MAX_DIRECTIONS = _untrusted.MAX_DIRECTIONS


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class DirectionSet:
    """Sample directions with their solid angles.

    Attributes
    ----------
    directions : ndarray, shape (S, 3), float64, read-only
        Unit vectors, world frame, z up.
    solid_angles : ndarray, shape (S,), float64, read-only
        Solid angle (sr) each sample stands for; sums to 4 pi.
    kind : str
        One of :data:`KINDS`, or ``"custom"`` for arrays given directly.
    params : dict
        Construction parameters (``{"n": 1024}``, ``{"rows": 32, "cols": 64}``, ...).
    """

    directions: np.ndarray
    solid_angles: np.ndarray
    kind: str
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        d = normalize_directions(self.directions)
        if d.ndim != 2:
            raise ValueError(f"directions must have shape (S, 3), got {d.shape}")
        w = np.asarray(self.solid_angles, dtype=np.float64)
        if w.shape != (d.shape[0],):
            raise ValueError(f"solid_angles must have shape ({d.shape[0]},), got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ValueError("solid_angles must be finite and positive (sr)")
        object.__setattr__(self, "directions", _readonly(d))
        object.__setattr__(self, "solid_angles", _readonly(w))
        object.__setattr__(self, "params", dict(self.params))

    @property
    def size(self) -> int:
        """Number of directions S."""
        return int(self.directions.shape[0])

    @property
    def spec(self) -> str:
        """Spec string that rebuilds this set (see :func:`parse_direction_spec`)."""
        p = self.params
        if self.kind == "halton":
            return f"halton:{p['n']}"
        if self.kind == "latlong":
            return f"latlong:{p['rows']}x{p['cols']}"
        if self.kind in ("cube", "cubegauss"):
            return f"{self.kind}:{p['n']}"
        if self.kind == "hemi":
            power = float(p.get("power", 1.0))
            return f"hemi:{p['n']}" if power == 1.0 else f"hemi:{p['n']}:{power:g}"
        return "custom"

    def to_dict(self, include_arrays: bool = False) -> dict:
        """JSON-safe description.

        Parameters
        ----------
        include_arrays : bool
            Also store the directions and solid angles as nested lists (always done for
            ``kind == "custom"``, which cannot be rebuilt from a spec).
        """
        out = {"kind": self.kind, "params": dict(self.params), "spec": self.spec,
               "size": self.size}
        if include_arrays or self.kind not in KINDS:
            out["directions"] = self.directions.tolist()
            out["solid_angles"] = self.solid_angles.tolist()
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "DirectionSet":
        """Inverse of :meth:`to_dict` (rebuilds from the spec when arrays are absent)."""
        if "directions" in data and "solid_angles" in data:
            for key in ("directions", "solid_angles"):   # (read from a file: count first)
                n = len(data[key]) if isinstance(data[key], (list, tuple, np.ndarray)) else -1
                if not 1 <= n <= MAX_DIRECTIONS:
                    raise InputError(f"a direction set's {key} must be a list of 1.."
                                     f"{MAX_DIRECTIONS} entries, got {n if n >= 0 else 'none'}")
            return cls(np.asarray(data["directions"], dtype=np.float64),
                       np.asarray(data["solid_angles"], dtype=np.float64),
                       data.get("kind", "custom"), data.get("params", {}))
        if "spec" in data:
            return parse_direction_spec(data["spec"])
        raise ValueError("direction-set dict needs a 'spec' or 'directions' + 'solid_angles'")


# ----------------------------------------------------------------------------------------------
# constructors


def _check_count(n, name: str) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {n!r}")
    n = int(n)
    if n < 1:
        raise ValueError(f"{name} must be >= 1, got {n}")
    return n


def radical_inverse(indices, base: int) -> np.ndarray:
    """Van der Corput radical inverse of non-negative integers in ``base``.

    Parameters
    ----------
    indices : array_like of int, shape (N,)
    base : int (>= 2)

    Returns
    -------
    ndarray, shape (N,), float64 in [0, 1)
    """
    i = np.asarray(indices, dtype=np.int64).copy()
    out = np.zeros(i.shape, dtype=np.float64)
    f = 1.0 / base
    while np.any(i > 0):
        out += f * (i % base)
        i //= base
        f /= base
    return out


def halton_sphere(n: int) -> DirectionSet:
    """Halton directions (bases 2, 3), area-uniform on the sphere, weights ``4 pi / n``.

    Parameters
    ----------
    n : int
        Number of directions. Points ``i = 1..n`` are used (``i = 0`` would be a pole).

    Returns
    -------
    DirectionSet, kind ``"halton"``
    """
    n = _check_count(n, "n")
    i = np.arange(1, n + 1)
    z = 1.0 - 2.0 * radical_inverse(i, 2)
    phi = 2.0 * np.pi * radical_inverse(i, 3)
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)
    return DirectionSet(d, np.full(n, 4.0 * np.pi / n), "halton", {"n": n})


def latlong(rows: int, cols: int) -> DirectionSet:
    """Cell centres of an equirectangular grid (row 0 at the top), exact cell solid angles.

    Parameters
    ----------
    rows, cols : int
        Cells in elevation and azimuth (``cols = 2 * rows`` gives square cells at the equator).

    Returns
    -------
    DirectionSet, kind ``"latlong"``, ``S = rows * cols``
    """
    rows = _check_count(rows, "rows")
    cols = _check_count(cols, "cols")
    u = (np.arange(cols) + 0.5) / cols
    v_top = 1.0 - np.arange(rows) / rows           # upper edge of each row (top first)
    v_bot = 1.0 - (np.arange(rows) + 1.0) / rows
    v_mid = 0.5 * (v_top + v_bot)
    uu, vv = np.meshgrid(u, v_mid)
    d = equirect_uv_to_direction(np.stack([uu, vv], axis=-1)).reshape(-1, 3)
    # elevation = (v - 0.5) * pi; cell solid angle = dphi * (sin el_top - sin el_bottom)
    band = np.sin((v_top - 0.5) * np.pi) - np.sin((v_bot - 0.5) * np.pi)
    w = np.repeat(band * (2.0 * np.pi / cols), cols)
    return DirectionSet(d, w, "latlong", {"rows": rows, "cols": cols})


def _cube_area(s, t):
    return np.arctan2(s * t, np.sqrt(s * s + t * t + 1.0))


def _face_directions(s, t):
    """Directions (6, *s.shape, 3) of face coordinates s, t (same on every face)."""
    f = CUBE_FACES
    d = (f[:, None, 0, :] + s.reshape(1, -1, 1) * f[:, None, 1, :]
         + t.reshape(1, -1, 1) * f[:, None, 2, :])
    return d.reshape((6,) + s.shape + (3,))


def cubemap(n: int) -> DirectionSet:
    """Texel centres of a cubemap with ``n x n`` texels per face and exact texel solid angles.

    Parameters
    ----------
    n : int
        Texels per face edge.

    Returns
    -------
    DirectionSet, kind ``"cube"``, ``S = 6 n^2``
        Solid angle of the texel ``[s0, s1] x [t0, t1]`` is
        ``A(s1, t1) - A(s0, t1) - A(s1, t0) + A(s0, t0)`` with
        ``A(s, t) = atan2(s t, sqrt(s^2 + t^2 + 1))``; they sum to 4 pi to rounding.
    """
    n = _check_count(n, "n")
    edges = np.linspace(-1.0, 1.0, n + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    tt, ss = np.meshgrid(centres, centres, indexing="ij")    # (row = t, col = s)
    d = _face_directions(ss, tt).reshape(-1, 3)
    t0, s0 = np.meshgrid(edges[:-1], edges[:-1], indexing="ij")
    t1, s1 = np.meshgrid(edges[1:], edges[1:], indexing="ij")
    face_w = _cube_area(s1, t1) - _cube_area(s0, t1) - _cube_area(s1, t0) + _cube_area(s0, t0)
    w = np.tile(face_w.ravel(), 6)
    return DirectionSet(d, w, "cube", {"n": n})


def cube_gauss(n: int) -> DirectionSet:
    """Gauss-Legendre quadrature on the six cube faces (``n x n`` nodes per face).

    The integrand on a face, ``f(d(s, t)) / (1 + s^2 + t^2)^{3/2}``, is analytic for smooth
    ``f`` (nearest complex singularity at ``|s| = 1``), so the rule converges geometrically:
    the weights sum to 4 pi within 4e-14 at ``n = 20`` and to rounding at ``n = 24``
    (4e-8 at ``n = 12``).

    Returns
    -------
    DirectionSet, kind ``"cubegauss"``, ``S = 6 n^2``, order as for :func:`cubemap`
    """
    n = _check_count(n, "n")
    x, wx = np.polynomial.legendre.leggauss(n)
    tt, ss = np.meshgrid(x, x, indexing="ij")
    ww = np.outer(wx, wx) / (1.0 + ss * ss + tt * tt) ** 1.5
    d = _face_directions(ss, tt).reshape(-1, 3)
    return DirectionSet(d, np.tile(ww.ravel(), 6), "cubegauss", {"n": n})


def hemisphere_fibonacci(n: int, power: float = 1.0) -> DirectionSet:
    """``n`` upper-hemisphere directions on a Fibonacci spiral, denser near the horizon for
    ``power > 1`` (see the module docstring, kind ``hemi``).

    Returns
    -------
    DirectionSet
        ``solid_angles`` sum to 2 pi (the upper hemisphere).
    """
    n = _check_count(n, "n")
    power = float(power)
    if not 1.0 <= power <= 4.0:
        raise ValueError(f"hemisphere power must be in [1, 4], got {power}")
    u = (np.arange(n) + 0.5) / n
    z = u ** power
    phi = np.arange(n) * (np.pi * (3.0 - np.sqrt(5.0)))
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)
    w = 2.0 * np.pi * power * u ** (power - 1.0) / n
    w *= 2.0 * np.pi / w.sum()   # exact total for any power (the midpoint rule is not)
    return DirectionSet(dirs, w, "hemi", {"n": n, "power": power})


def make_direction_set(kind: str, **params) -> DirectionSet:
    """Build a set by kind name: ``make_direction_set("cube", n=16)``."""
    builders = {"halton": lambda p: halton_sphere(p["n"]),
                "latlong": lambda p: latlong(p["rows"], p["cols"]),
                "cube": lambda p: cubemap(p["n"]),
                "cubegauss": lambda p: cube_gauss(p["n"]),
                "hemi": lambda p: hemisphere_fibonacci(p["n"], p.get("power", 1.0))}
    if kind not in builders:
        raise ValueError(f"unknown direction-set kind {kind!r}; expected one of {KINDS}")
    try:
        return builders[kind](params)
    except KeyError as exc:
        raise ValueError(f"direction-set kind {kind!r} needs parameter {exc.args[0]!r}") from None


def parse_direction_spec(spec: str) -> DirectionSet:
    """Build a direction set from a spec string.

    Parameters
    ----------
    spec : str
        ``"halton:N"``, ``"latlong:ROWSxCOLS"``, ``"cube:N"`` (N texels per face edge) or
        ``"cubegauss:N"``. Case and surrounding spaces are ignored.

    Returns
    -------
    DirectionSet

    Raises
    ------
    ValueError
        With the accepted forms, for anything else (unknown kind, missing or non-positive
        numbers, more than :data:`MAX_DIRECTIONS` directions).
    """
    forms = "'halton:1024', 'latlong:32x64', 'cube:16', 'cubegauss:12' or 'hemi:400[:1.5]'"
    if not isinstance(spec, str):
        raise ValueError(f"direction spec must be a string like {forms}, got {spec!r}")
    text = spec.strip().lower()
    kind, sep, arg = text.partition(":")
    if not sep or kind not in KINDS:
        raise ValueError(f"bad direction spec {spec!r}; expected {forms}")

    def _int(s: str) -> int:
        s = s.strip()
        if not s.isdigit() or int(s) < 1:
            raise ValueError(f"bad direction spec {spec!r}: {s!r} is not a positive integer; "
                             f"expected {forms}")
        return int(s)

    if kind == "hemi":
        count, _, power = arg.partition(":")
        n = _int(count)
        try:
            p = float(power) if power else 1.0
        except ValueError:
            p = float("nan")
        if not 1.0 <= p <= 4.0:
            raise ValueError(f"bad direction spec {spec!r}: the horizon power must be a number "
                             "in [1, 4], e.g. 'hemi:400:1.5'")
        if n > MAX_DIRECTIONS:
            raise InputError(f"direction spec {spec!r} asks for {n} directions; the limit is "
                             f"{MAX_DIRECTIONS}")
        return hemisphere_fibonacci(n, p)
    if kind == "latlong":
        parts = arg.split("x")
        if len(parts) != 2:
            raise ValueError(f"bad direction spec {spec!r}: latlong needs ROWSxCOLS, "
                             "e.g. 'latlong:32x64'")
        rows, cols = _int(parts[0]), _int(parts[1])
        total = rows * cols
    else:
        n = _int(arg)
        total = n if kind == "halton" else 6 * n * n
    if total > MAX_DIRECTIONS:
        raise InputError(f"direction spec {spec!r} asks for {total} directions; the limit is "
                         f"{MAX_DIRECTIONS}")
    if kind == "latlong":
        return latlong(rows, cols)
    return make_direction_set(kind, n=n)


# ----------------------------------------------------------------------------------------------
# queries


def upper_hemisphere_mask(directions, normals) -> np.ndarray:
    """Which sample directions lie strictly above each vertex's tangent plane.

    Parameters
    ----------
    directions : array_like, shape (S, 3)
    normals : array_like, shape (V, 3)
        Need not be unit length (only the sign of the dot product matters).

    Returns
    -------
    mask : ndarray of bool, shape (V, S)
        ``n_v . w_j > 0``.
    """
    d = normalize_directions(directions)
    n = normalize_directions(normals)
    if d.ndim != 2 or n.ndim != 2:
        raise ValueError(f"directions (S, 3) and normals (V, 3) expected, got {d.shape}, "
                         f"{n.shape}")
    return n @ d.T > 0.0


def nearest_directions(direction_set: DirectionSet, query, k: int = 1):
    """Indices of the ``k`` sample directions closest in angle to each query direction.

    Parameters
    ----------
    direction_set : DirectionSet
    query : array_like, shape (Q, 3)
    k : int

    Returns
    -------
    indices : ndarray of int, shape (Q, k)
    angles : ndarray, shape (Q, k), radians, ascending
    """
    q = normalize_directions(query)
    k = _check_count(k, "k")
    if k > direction_set.size:
        raise ValueError(f"k = {k} exceeds the {direction_set.size} sample directions")
    tree = scipy.spatial.cKDTree(direction_set.directions)
    chord, idx = tree.query(q.reshape(-1, 3), k=k)
    chord = np.asarray(chord).reshape(-1, k)
    idx = np.asarray(idx).reshape(-1, k)
    angles = 2.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0))
    return idx, angles


def cube_face_coordinates(directions):
    """Face index and face coordinates ``(s, t)`` in [-1, 1] of directions (see :data:`CUBE_FACES`).

    Parameters
    ----------
    directions : array_like, shape (Q, 3)

    Returns
    -------
    face : ndarray of int, shape (Q,)
    s, t : ndarray, shape (Q,)
    """
    d = normalize_directions(directions).reshape(-1, 3)
    axis = np.argmax(np.abs(d), axis=1)
    sign = np.take_along_axis(d, axis[:, None], axis=1)[:, 0] >= 0
    face = 2 * axis + np.where(sign, 0, 1)
    f = CUBE_FACES[face]
    ma = np.abs(np.take_along_axis(d, axis[:, None], axis=1)[:, 0])
    s = np.einsum("qi,qi->q", d, f[:, 1]) / ma
    t = np.einsum("qi,qi->q", d, f[:, 2]) / ma
    return face, np.clip(s, -1.0, 1.0), np.clip(t, -1.0, 1.0)


def _bilinear_corners(x, size, wrap: bool):
    """Lower index, upper index and weight of the upper one for continuous coordinate x."""
    if wrap:
        x0 = np.floor(x)
        f = x - x0
        i0 = np.mod(x0.astype(np.int64), size)
        return i0, np.mod(i0 + 1, size), f
    x = np.clip(x, 0.0, size - 1.0)
    x0 = np.minimum(np.floor(x), max(size - 2, 0)).astype(np.int64)
    f = x - x0
    return x0, np.minimum(x0 + 1, size - 1), f


def _hull_interpolation(direction_set: DirectionSet, q: np.ndarray):
    """Vertex indices (Q, 3) and barycentric weights (Q, 3) on the convex hull of the samples."""
    hull = scipy.spatial.ConvexHull(direction_set.directions)
    eq = hull.equations                       # n . x + off <= 0 inside, off < 0 (origin inside)
    if np.any(eq[:, 3] >= 0):
        raise ValueError("the sample directions do not surround the origin; cannot interpolate")
    return hull_barycentric(direction_set.directions, hull.simplices, eq, q)


def hull_barycentric(points, simplices, equations, q):
    """Triangle (Q, 3) and barycentric weights (Q, 3) where the rays ``t q`` leave a convex hull
    (``points`` (P, 3), its ``simplices`` and facet ``equations`` from scipy, origin inside)."""
    # the ray t * q leaves the hull through the facet with the largest (n . q) / (-off)
    score = (q @ equations[:, :3].T) / (-equations[:, 3])
    facet = np.argmax(score, axis=1)
    tri = simplices[facet]                       # (Q, 3)
    p = q / score[np.arange(q.shape[0]), facet][:, None]   # hit point on the facet plane
    from ..geometry.barycentric import barycentric

    a, b, c = (points[tri[:, i]] for i in range(3))
    return tri, barycentric(p, a, b, c)


def interpolation_weights(direction_set: DirectionSet, query, method: str = "auto"):
    """Sparse linear interpolation of per-sample values at arbitrary directions.

    Parameters
    ----------
    direction_set : DirectionSet
    query : array_like, shape (Q, 3)
    method : {"auto", "lattice", "hull", "nearest"}
        ``"lattice"``: bilinear on the set's own grid (``latlong``: wraps in azimuth, clamps
        at the top and bottom rows; ``cube``: bilinear inside the face, clamped at the face
        edges -- the simple scheme of the paper's sec. 5). ``"hull"``: barycentric on the
        triangulated convex hull of the sample directions (any set). ``"nearest"``: the
        closest sample. ``"auto"``: lattice for ``latlong`` and ``cube``, hull otherwise.

    Returns
    -------
    indices : ndarray of int, shape (Q, K)
    weights : ndarray, shape (Q, K), float64, rows sum to 1 (K = 4 lattice, 3 hull, 1 nearest)
    """
    q = normalize_directions(query).reshape(-1, 3)
    kind = direction_set.kind
    if method == "auto":
        method = "lattice" if kind in ("latlong", "cube") else "hull"
    if method == "nearest":
        idx, _ = nearest_directions(direction_set, q, 1)
        return idx, np.ones(idx.shape)
    if method == "hull":
        return _hull_interpolation(direction_set, q)
    if method != "lattice":
        raise ValueError(f"method must be 'auto', 'lattice', 'hull' or 'nearest', got {method!r}")
    if kind == "latlong":
        rows, cols = direction_set.params["rows"], direction_set.params["cols"]
        uv = direction_to_equirect_uv(q)
        x = uv[:, 0] * cols - 0.5
        y = (1.0 - uv[:, 1]) * rows - 0.5          # row coordinate, row 0 at the top
        c0, c1, fx = _bilinear_corners(x, cols, wrap=True)
        r0, r1, fy = _bilinear_corners(y, rows, wrap=False)
        idx = np.stack([r0 * cols + c0, r0 * cols + c1, r1 * cols + c0, r1 * cols + c1], -1)
        w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], -1)
        return idx, w
    if kind == "cube":
        n = direction_set.params["n"]
        face, s, t = cube_face_coordinates(q)
        c0, c1, fx = _bilinear_corners((s + 1.0) * 0.5 * n - 0.5, n, wrap=False)
        r0, r1, fy = _bilinear_corners((t + 1.0) * 0.5 * n - 0.5, n, wrap=False)
        base = face * n * n
        idx = np.stack([base + r0 * n + c0, base + r0 * n + c1, base + r1 * n + c0,
                        base + r1 * n + c1], -1)
        w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], -1)
        return idx, w
    raise ValueError(f"direction set of kind {kind!r} is not a lattice; use method='hull'")


def interpolate_samples(direction_set: DirectionSet, values, query, method: str = "auto"):
    """Interpolate per-sample values at query directions (see :func:`interpolation_weights`).

    Parameters
    ----------
    direction_set : DirectionSet
    values : array_like, shape (S,) or (S, C)
    query : array_like, shape (Q, 3)
    method : str

    Returns
    -------
    ndarray, shape (Q,) or (Q, C), float64
    """
    v = np.asarray(values, dtype=np.float64)
    if v.shape[:1] != (direction_set.size,) or v.ndim > 2:
        raise ValueError(f"values must have shape ({direction_set.size},) or "
                         f"({direction_set.size}, C), got {v.shape}")
    idx, w = interpolation_weights(direction_set, query, method)
    if v.ndim == 1:
        return np.sum(v[idx] * w, axis=1)
    return np.einsum("qk,qkc->qc", w, v[idx])
