"""Sun-moving bounce light for engines (bpy-free): a few basis lightmaps and a small table of
their weights over the sun's direction.

Engines light the direct sun in real time; what they cannot do cheaply is the bounce light
of a *moving* sun (Godot's LightmapGI is static; SDFGI/HDDAGI flicker and converge slowly).
A transport bake has that term for every sun direction (``bake.indirect``), and it is smooth
and low-dimensional, so

    indirect(texel, sun) ~= sum_k table_k(sun) * basis_k(texel)

with K basis images from an SVD of the term sampled on a grid of sun directions, and the
table holding each grid direction's K weights. An engine fetches the table bilinearly at the
sun's direction and sums K texture fetches: the ~30-line shader this module writes.

Grid: azimuth ``a_i = 2 pi i / NA`` (i < NA; it wraps) by elevation
``e_j = (pi / 2) j / (NE - 1)`` (j < NE), in Blender's world frame (z up, azimuth from +x
towards +y). Table texel (i, j) -- column i, row j from the top -- is sampled at
``u = a / 2 pi + 0.5 / NA`` (repeat) and ``v = (e / (pi / 2)) (NE - 1) / NE + 0.5 / NE``
(clamp), so bilinear filtering interpolates between grid directions.

Units: the basis holds outgoing radiance (W m^-2 sr^-1) per unit sun strength (W m^-2), linear
Rec. 709, the albedo included (what the bake's indirect term is); the table is unitless.
Arrays: basis (K, R, R, 3) row 0 at texture v = 0; table (NE, NA, K).
"""

from __future__ import annotations

import json
import os

import numpy as np

from ..io import atomic, exrio

#: Grid of sun directions (azimuths x elevations).
GRID = (32, 9)
#: At most this many basis images (two RGBA tables in the shader).
MAX_COMPONENTS = 8
#: The smallest K whose held-out error is below this is chosen (relative RMS).
TARGET_ERROR = 0.01


def grid_directions(grid=GRID) -> np.ndarray:
    """Directions (NE, NA, 3) of the table's texels."""
    na, ne = grid
    a = 2.0 * np.pi * np.arange(na) / na
    e = 0.5 * np.pi * np.arange(ne) / (ne - 1)
    A, E = np.meshgrid(a, e)
    return np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1)


def table_coordinates(direction, grid=GRID) -> tuple[float, float]:
    """Texture coordinates (u, v) of a sun direction (3,) in the table (v = 0 on top)."""
    na, ne = grid
    d = np.asarray(direction, np.float64)
    a = np.arctan2(d[1], d[0]) % (2.0 * np.pi)
    e = np.arcsin(np.clip(d[2], 0.0, 1.0))
    return a / (2 * np.pi) + 0.5 / na, (e / (0.5 * np.pi)) * (ne - 1) / ne + 0.5 / ne


def bilinear(table, u: float, v: float) -> np.ndarray:
    """What a GPU's bilinear fetch of ``table`` (NE, NA, K) returns at (u, v): repeat in u,
    clamp to edge in v (texel centres at (i + 0.5) / size)."""
    ne, na, _ = table.shape
    x, y = u * na - 0.5, v * ne - 0.5
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - x0, y - y0
    xs = [x0 % na, (x0 + 1) % na]
    ys = [min(max(y0, 0), ne - 1), min(max(y0 + 1, 0), ne - 1)]
    top = (1 - fx) * table[ys[0], xs[0]] + fx * table[ys[0], xs[1]]
    bottom = (1 - fx) * table[ys[1], xs[0]] + fx * table[ys[1], xs[1]]
    return (1 - fy) * top + fy * bottom


def fit(sample, held_out, components: int | None = None, grid=GRID):
    """Basis and table from ``sample`` (direction (3,) -> radiance (R, R, 3)), with the
    relative RMS error of the bilinear table at the ``held_out`` directions (H, 3).

    float64 SVD of the (grid directions, texels x 3) matrix; the basis is scaled so table
    weights are O(1). ``components`` None picks the smallest K <= MAX_COMPONENTS under
    TARGET_ERROR (else MAX_COMPONENTS).

    Returns (basis (K, R, R, 3) float32, table (NE, NA, K) float32, figures dict).
    """
    dirs = grid_directions(grid)
    ne, na, _ = dirs.shape
    first = np.asarray(sample(dirs[0, 0]), np.float64)
    shape = first.shape
    X = np.empty((ne * na, first.size))
    for i, d in enumerate(dirs.reshape(-1, 3)):
        X[i] = first.reshape(-1) if i == 0 else np.asarray(sample(d), np.float64).reshape(-1)
    U, s, Vt = np.linalg.svd(X, full_matrices=False)
    truths = [np.asarray(sample(d), np.float64).reshape(-1) for d in held_out]
    norm = np.sqrt(np.mean([np.mean(t ** 2) for t in truths]))
    errors = {}
    for k in range(1, min(MAX_COMPONENTS, len(s)) + 1):
        table = (U[:, :k] * s[:k]).reshape(ne, na, k)
        err = []
        for d, t in zip(held_out, truths):
            w = bilinear(table, *table_coordinates(d, grid))
            err.append(np.mean((w @ Vt[:k] - t) ** 2))
        errors[k] = float(np.sqrt(np.mean(err)) / norm) if norm > 0 else 0.0
    if components is None:
        K = next((k for k, e in errors.items() if e <= TARGET_ERROR), max(errors))
    else:
        K = int(components)
        if not 1 <= K <= min(MAX_COMPONENTS, len(s)):
            raise ValueError(f"components must be in 1..{min(MAX_COMPONENTS, len(s))}")
    scale = s[:K] / np.sqrt(ne * na)                 # weights O(1): U's columns are unit
    table = (U[:, :K] * np.sqrt(ne * na)).reshape(ne, na, K)
    basis = (Vt[:K] * scale[:, None]).reshape(K, *shape)
    figures = {"components": K, "error_by_components": {str(k): round(e, 5)
                                                        for k, e in errors.items()},
               "error_vs_our_relight": round(errors[K], 5), "held_out_suns": len(held_out),
               "grid": {"azimuths": na, "elevations": ne},
               "singular_values": [float(v) for v in s[:MAX_COMPONENTS]]}
    return basis.astype(np.float32), table.astype(np.float32), figures


def evaluate(basis, table, direction, grid=GRID) -> np.ndarray:
    """The shader's sum at a sun direction: (R, R, 3); 0 for a sun below the horizon."""
    if direction[2] < 0:
        return np.zeros(basis.shape[1:], np.float64)
    w = bilinear(np.asarray(table, np.float64), *table_coordinates(direction, grid))
    return np.einsum("k,kxyc->xyc", w, np.asarray(basis, np.float64))


GDSHADER = """\
// Relightable Textures: bounce light of a moving sun ({K} basis lightmaps, a {NA}x{NE} table
// of their weights over the sun's direction). Engines do the direct sun in real time; add
// this to the mesh's material (or use it as is) and set sun_direction from your
// DirectionalLight3D: sun_direction = light.global_transform.basis.z (towards the sun).
shader_type spatial;

uniform sampler2DArray basis : filter_linear, repeat_disable;      // {name}_basis.exr
uniform sampler2D table_0 : filter_linear, repeat_enable;         // {name}_table_0.exr
uniform sampler2D table_1 : filter_linear, repeat_enable;         // {name}_table_1.exr
uniform vec3 sun_direction = vec3(0.0, 1.0, 0.0);                 // world, towards the sun
uniform float sun_energy = 1.0;                                   // W/m^2 of the bake's sun
uniform vec3 albedo : source_color = vec3(1.0);
varying vec2 lightmap_uv;

void vertex() {{
	lightmap_uv = UV2;
}}

void fragment() {{
	ALBEDO = albedo;
	vec3 d = normalize(sun_direction);           // Godot (x, y, z) = Blender (x, z, -y)
	float az = mod(atan(-d.z, d.x), TAU);
	float el = asin(clamp(d.y, 0.0, 1.0));
	vec2 t = vec2(az / TAU + {HU}, el / (PI / 2.0) * {VS} + {HV});
	vec4 w0 = texture(table_0, t);
	vec4 w1 = texture(table_1, t);
	float w[8] = float[8](w0.r, w0.g, w0.b, w0.a, w1.r, w1.g, w1.b, w1.a);
	vec3 bounce = vec3(0.0);
	for (int k = 0; k < {K}; k++) {{
		bounce += w[k] * texture(basis, vec3(lightmap_uv, float(k))).rgb;
	}}
	EMISSION = d.y >= 0.0 ? bounce * sun_energy : vec3(0.0);
}}
"""


def gdshader(name: str, K: int, grid=GRID) -> str:
    na, ne = grid
    return GDSHADER.format(K=K, NA=na, NE=ne, name=name, HU=f"{0.5 / na:.8f}",
                           VS=f"{(ne - 1) / ne:.8f}", HV=f"{0.5 / ne:.8f}")


#: The tables' ``.import``: a Texture2D kept as floats (VRAM Uncompressed), no mipmaps, and
#: no switch to VRAM compression when Godot sees it used in 3D (the weights are signed).
TABLE_IMPORT = ("[remap]\n\nimporter=\"texture\"\ntype=\"CompressedTexture2D\"\n\n[params]\n\n"
                "compress/mode=3\nmipmaps/generate=false\ndetect_3d/compress_to=0\n")


def exposure_for(basis, table) -> float:
    """The page's exposure: the 99.5th percentile of the bounce light at the table's
    directions maps to 1."""
    vals = np.einsum("sk,kp->sp", np.asarray(table, np.float64).reshape(-1, table.shape[-1]),
                     np.asarray(basis, np.float64).reshape(basis.shape[0], -1))
    p = float(np.percentile(vals, 99.5))
    return 1.0 / p if p > 0 else 1.0


def page(basis, table, figures: dict, exposure: float, title: str) -> str:
    """The self-contained web page (``web/sun_indirect.html`` + ``.js``): the basis and table
    embedded as float32 base64, summed on the CPU as the sun sliders move."""
    import base64
    import html

    web = os.path.join(os.path.dirname(__file__), "web")
    with open(os.path.join(web, "sun_indirect.html")) as fh:
        text = fh.read()
    with open(os.path.join(web, "sun_indirect.js")) as fh:
        js = fh.read()
    K, R = basis.shape[0], basis.shape[1]
    info = {"components": K, "resolution": R, "grid": figures["grid"],
            "exposure": float(exposure)}
    b64 = lambda a: base64.b64encode(np.ascontiguousarray(a, "<f4").tobytes()).decode()
    return (text.replace("{{TITLE}}", html.escape(f"{title}: bounce light of a moving sun"))
            .replace("{{K}}", str(K)).replace("{{INFO}}", json.dumps(info))
            .replace("{{BASIS}}", b64(basis)).replace("{{TABLE}}", b64(table))
            .replace("{{VIEWER}}", js))


def write(folder: str, basis, table, figures: dict, metadata: dict, grid=GRID) -> dict:
    """Write the folder atomically: ``<stem>_basis.exr`` (K layers stacked vertically, layer 0
    on top, each band's top row v = 1, as Godot's 2D array import slices it) and its
    ``.import``, ``<stem>_table_0.exr`` / ``_1.exr`` (RGBA = weights 0-3 / 4-7; row 0 on top
    = elevation 0), ``<stem>.gdshader``, ``<stem>.json`` (the decode, grid and errors) and
    ``index.html`` (our page: sun sliders over the same sum)."""
    from .godot import import_text

    folder = os.path.abspath(folder)
    stem = os.path.basename(folder)
    K, R = basis.shape[0], basis.shape[1]
    exposure = exposure_for(basis, table)
    figures = {**figures, "page_exposure": exposure}
    names = {"basis": f"{stem}_basis.exr", "table_0": f"{stem}_table_0.exr",
             "table_1": f"{stem}_table_1.exr", "shader": f"{stem}.gdshader",
             "about": f"{stem}.json", "page": "index.html"}
    with atomic.staged_folder(folder) as tmp:
        img = np.concatenate([b[::-1] for b in basis], axis=0)            # top row first
        exrio.write_exr(os.path.join(tmp, names["basis"]),
                        {c: img[::-1, :, i] for i, c in enumerate("RGB")},
                        {**metadata, "layers": K}, pixel_type="half")
        atomic.write_text(os.path.join(tmp, names["basis"] + ".import"),
                          import_text(slices=K))
        for t in (0, 1):           # float, uncompressed: weights are signed (BC6H is not)
            atomic.write_text(os.path.join(tmp, names[f"table_{t}"] + ".import"),
                              TABLE_IMPORT)
        padded = np.zeros(table.shape[:2] + (8,), np.float32)
        padded[..., :K] = table
        for t in (0, 1):
            ch = {c: padded[::-1, :, 4 * t + i] for i, c in enumerate("RGBA")}  # row 0 on top
            exrio.write_exr(os.path.join(tmp, names[f"table_{t}"]), ch,
                            {**metadata, "weights": f"{4 * t}..{4 * t + 3}"}, pixel_type="float")
        atomic.write_text(os.path.join(tmp, names["shader"]), gdshader(stem, K, grid))
        about = {**metadata, **figures, "resolution": R, "files": names,
                 "decode": "radiance(uv2) = sum_k table_k(u, v) basis_k(uv2), (u, v) = "
                           "(az / 2pi + 0.5 / NA, el / (pi/2) (NE - 1) / NE + 0.5 / NE), "
                           "az/el of the sun in Blender's world frame; 0 below the horizon",
                 "units": "outgoing radiance (W m^-2 sr^-1) per W/m^2 of sun, albedo "
                          "included, linear Rec.709"}
        atomic.write_json(os.path.join(tmp, names["about"]), about, indent=1)
        atomic.write_text(os.path.join(tmp, names["page"]),
                          page(basis, table, figures, exposure, metadata.get("object", stem)))
    return {k: os.path.join(folder, v) for k, v in names.items()}
