// Relightable Textures -- the bounce light of a moving sun, as `relight export --format
// sun-indirect` writes it: K basis lightmaps and a table of their weights over the sun's
// direction (lt_addon/export/sun_indirect.py). The page embeds both (float32, base64) and
// sums them on the CPU when the sun moves (the sliders, sunIndirectSet(az, el) or the URL hash
// #sun=az,el in degrees). Shown: radiance x exposure, sRGB-encoded, top row first.
"use strict";

(function () {
  const INFO = JSON.parse(document.getElementById("si-info").textContent);
  const floats = (id) => {
    const bin = atob(document.getElementById(id).textContent.trim());
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new Float32Array(bytes.buffer);
  };
  const BASIS = floats("si-basis");            // (K, R, R, 3), row 0 at v = 0
  const TABLE = floats("si-table");            // (NE, NA, K), row 0 = elevation 0
  const K = INFO.components, R = INFO.resolution, NA = INFO.grid.azimuths;
  const NE = INFO.grid.elevations;

  function weights(azDeg, elDeg) {             // the shader's bilinear fetch
    const az = ((azDeg % 360) + 360) % 360 * Math.PI / 180;
    const el = Math.min(Math.max(elDeg, 0), 90) * Math.PI / 180;
    const u = az / (2 * Math.PI) + 0.5 / NA, v = el / (Math.PI / 2) * (NE - 1) / NE + 0.5 / NE;
    const x = u * NA - 0.5, y = v * NE - 0.5;
    const x0 = Math.floor(x), y0 = Math.floor(y), fx = x - x0, fy = y - y0;
    const col = (i) => ((i % NA) + NA) % NA, row = (j) => Math.min(Math.max(j, 0), NE - 1);
    const w = new Float64Array(K);
    for (let k = 0; k < K; k++) {
      const t = (j, i) => TABLE[(row(j) * NA + col(i)) * K + k];
      w[k] = (1 - fy) * ((1 - fx) * t(y0, x0) + fx * t(y0, x0 + 1))
           + fy * ((1 - fx) * t(y0 + 1, x0) + fx * t(y0 + 1, x0 + 1));
    }
    return w;
  }

  const srgb = (x) => (x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055);
  const canvas = document.getElementById("si-canvas");
  const ctx = canvas.getContext("2d");
  canvas.width = R; canvas.height = R;
  const zoom = Math.max(1, Math.ceil(512 / R));
  canvas.style.width = R * zoom + "px"; canvas.style.height = R * zoom + "px";
  const out = ctx.createImageData(R, R);
  const status = document.getElementById("si-status");
  const azIn = document.getElementById("si-az"), elIn = document.getElementById("si-el");

  function render(azDeg, elDeg) {
    const w = weights(azDeg, elDeg), d = out.data, n = R * R * 3;
    for (let row = 0; row < R; row++) {
      const src = R - 1 - row;                 // canvas row 0 = texture v = 1
      for (let col = 0; col < R; col++) {
        const p = (src * R + col) * 3, o = 4 * (row * R + col);
        for (let c = 0; c < 3; c++) {
          let v = 0;
          if (elDeg >= 0) for (let k = 0; k < K; k++) v += w[k] * BASIS[k * n + p + c];
          d[o + c] = Math.round(Math.min(1, Math.max(0, srgb(Math.max(0, v * INFO.exposure)))) * 255);
        }
        d[o + 3] = 255;
      }
    }
    ctx.putImageData(out, 0, 0);
    window.sunIndirectSun = [azDeg, elDeg];
    status.textContent = `sun azimuth ${azDeg.toFixed(1)}, elevation ${elDeg.toFixed(1)} deg`;
  }

  window.sunIndirectSet = function (az, el) {
    azIn.value = az; elIn.value = el;
    render(az, el);
  };
  const update = () => render(parseFloat(azIn.value), parseFloat(elIn.value));
  azIn.addEventListener("input", update);
  elIn.addEventListener("input", update);
  const m = /sun=([-0-9.]+),([-0-9.]+)/.exec(window.location.hash);
  if (m) window.sunIndirectSet(parseFloat(m[1]), parseFloat(m[2]));
  else update();
  document.body.dataset.ready = "1";
})();
