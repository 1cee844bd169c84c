// Relightable Textures -- a minimal RTI viewer (PTM and HSH, rgb colour space) for the planes
// written by `relight export --format rti-ptm|rti-hsh`. No dependencies: the page embeds the
// info.json object and the plane images; this script decodes the planes once and relights
// every pixel on the CPU when the light moves (drag or move the mouse over the picture, or set
// it with relightSetLight(x, y) or the URL hash #light=x,y).
//
// The arithmetic is the exporter's (lt_addon/export/rti.py and rti_files.py): coefficient
// c = (byte / 255 - bias) * scale, value = sum_k basis_k(light) c_k, shown as
// round(clamp(value, 0, 1) * 255) -- the planes hold sRGB display values.
"use strict";

(function () {
  const INFO = JSON.parse(document.getElementById("rti-info").textContent);
  const PLANES = JSON.parse(document.getElementById("rti-planes").textContent);

  function ptmBasis(lx, ly) {          // the relight tools' (and OpenLIME's) order
    return [1.0, lx, ly, lx * lx, lx * ly, ly * ly];
  }

  function legendre(l, m, x) {       // P_l^m(x), Condon-Shortley phase, m >= 0
    let pmm = 1.0;
    if (m > 0) {
      const somx2 = Math.sqrt(Math.max(0, (1 - x) * (1 + x)));
      let fact = 1.0;
      for (let i = 0; i < m; i++) { pmm = -pmm * fact * somx2; fact += 2.0; }
    }
    if (l === m) return pmm;
    let pmmp1 = x * (2 * m + 1) * pmm;
    if (l === m + 1) return pmmp1;
    let pll = pmmp1;
    for (let ll = m + 2; ll <= l; ll++) {
      pll = ((2 * ll - 1) * x * pmmp1 - (ll + m - 1) * pmm) / (ll - m);
      pmm = pmmp1; pmmp1 = pll;
    }
    return pll;
  }

  function factorial(n) { let f = 1; for (let i = 2; i <= n; i++) f *= i; return f; }

  // hemispherical harmonics in the relight tools' conventions: per order m = +l .. -l, every
  // m != 0 term negated, the light clamped 0.15 rad above the horizon (OpenLIME's
  // HSH.minElevation, which the exporter fits with)
  function hshBasis(lx, ly, lz, terms) {
    const order = Math.round(Math.sqrt(terms));
    const theta = Math.min(Math.acos(Math.min(1, Math.max(-1, lz))), Math.PI / 2 - 0.15);
    const x = 2.0 * Math.cos(theta) - 1.0;
    const phi = Math.atan2(ly, lx);
    const out = [];
    for (let l = 0; l < order; l++) {
      for (let m = l; m >= -l; m--) {
        const am = Math.abs(m);
        const k = Math.sqrt((2 * l + 1) * factorial(l - am) / (2 * Math.PI * factorial(l + am)));
        const p = legendre(l, am, x);
        if (m === 0) out.push(k * p);
        else if (m > 0) out.push(-Math.SQRT2 * k * Math.cos(m * phi) * p);
        else out.push(-Math.SQRT2 * k * Math.sin(am * phi) * p);
      }
    }
    return out;
  }

  function basis(lx, ly, lz) {
    const terms = INFO.nplanes / 3;
    return INFO.type === "ptm" ? ptmBasis(lx, ly) : hshBasis(lx, ly, lz, terms);
  }

  // light from a point of the picture: the disc inscribed in it is the hemisphere seen from
  // above (x right, y up); outside the disc the light is on the horizon
  function lightFromPoint(px, py, w, h) {
    let x = (2 * px) / w - 1, y = 1 - (2 * py) / h;
    const r = Math.hypot(x, y);
    if (r > 1) { x /= r; y /= r; }
    return [x, y, Math.sqrt(Math.max(0, 1 - x * x - y * y))];
  }

  const canvas = document.getElementById("rti-canvas");
  const ctx = canvas.getContext("2d");
  const W = INFO.width, H = INFO.height;
  canvas.width = W; canvas.height = H;
  const zoom = Math.max(1, Math.ceil(512 / Math.max(W, H)));
  canvas.style.width = W * zoom + "px"; canvas.style.height = H * zoom + "px";
  const status = document.getElementById("rti-status");
  let coeffs = null;                 // Float64Array, (pixel, plane) with plane = 3 k + channel
  const out = ctx.createImageData(W, H);

  function decodePlanes(images) {
    const n = INFO.nplanes;
    coeffs = new Float64Array(W * H * n);
    const scratch = document.createElement("canvas");
    scratch.width = W; scratch.height = H;
    const sctx = scratch.getContext("2d", { willReadFrequently: true });
    images.forEach((img, j) => {
      sctx.clearRect(0, 0, W, H);
      sctx.drawImage(img, 0, 0);
      const px = sctx.getImageData(0, 0, W, H).data;
      for (let c = 0; c < 3; c++) {
        const plane = 3 * j + c;
        const s = INFO.materials[0].scale[plane], b = INFO.materials[0].bias[plane];
        for (let i = 0; i < W * H; i++) coeffs[i * n + plane] = (px[4 * i + c] / 255 - b) * s;
      }
    });
  }

  function render(light) {
    const base = basis(light[0], light[1], light[2]);
    const n = INFO.nplanes, K = n / 3, d = out.data;
    for (let i = 0; i < W * H; i++) {
      const o = i * n;
      for (let c = 0; c < 3; c++) {
        let v = 0;
        for (let k = 0; k < K; k++) v += base[k] * coeffs[o + 3 * k + c];
        d[4 * i + c] = Math.round(Math.min(1, Math.max(0, v)) * 255);
      }
      d[4 * i + 3] = 255;
    }
    ctx.putImageData(out, 0, 0);
    window.relightLight = light;
    status.textContent = `light (${light.map((v) => v.toFixed(3)).join(", ")})`;
  }

  window.relightSetLight = function (x, y) {
    const r = Math.hypot(x, y);
    if (r > 1) { x /= r; y /= r; }
    render([x, y, Math.sqrt(Math.max(0, 1 - x * x - y * y))]);
  };

  function fromEvent(ev) {
    const rect = canvas.getBoundingClientRect();
    render(lightFromPoint(ev.clientX - rect.left, ev.clientY - rect.top, rect.width,
                          rect.height));
  }

  canvas.addEventListener("mousemove", fromEvent);
  canvas.addEventListener("click", fromEvent);

  Promise.all(PLANES.map((src) => new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error("cannot decode a plane"));
    img.src = src;
  }))).then((images) => {
    decodePlanes(images);
    const m = /light=([-0-9.]+),([-0-9.]+)/.exec(window.location.hash);
    if (m) window.relightSetLight(parseFloat(m[1]), parseFloat(m[2]));
    else window.relightSetLight(0.3, 0.3);
    document.body.dataset.ready = "1";
  }).catch((err) => { status.textContent = String(err); });
})();
