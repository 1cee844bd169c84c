// Load an exported RTI folder in OpenLIME itself (its ES modules, served from their own
// folder; never copied into this repository) in headless Chromium, set each given light, and
// save the canvas's pixels. The canvas is sized to the image, so OpenLIME's camera fits it
// 1:1 (Camera.js fit: z = min(w / imgW, h / imgH) = 1) and canvas row r is the JPEG's row r.
//
// Usage: node openlime.mjs OPENLIME_SRC EXPORT_DIR OUT_PREFIX x1,y1 [x2,y2 ...]
// Prints one JSON line per light: {"light": [x, y], "rgba": path of W*H*4 raw bytes, "width",
// "height"}, then {"requests": [...], "failed": [...]} (a 404 or failed request fails the run).
import http from "node:http";
import fs from "node:fs";
import path from "node:path";
import { chromium } from "playwright-core";

const [srcDir, exportDir, prefix, ...lights] = process.argv.slice(2);
const info = JSON.parse(fs.readFileSync(path.join(exportDir, "info.json"), "utf8"));
const W = info.width, H = info.height;
const TYPES = { ".js": "text/javascript", ".html": "text/html", ".json": "application/json",
                ".jpg": "image/jpeg" };

// The page: OpenLIME's Viewer with one RTI layer in the "image" layout (plane_<k>.jpg next
// to info.json), as its own examples build it.
const PAGE = `<!doctype html><html><head><meta charset="utf-8"><link rel="icon" href="data:,">
<style>body{margin:0}#v{position:absolute;left:0;top:0}#v canvas{display:block}</style></head>
<body><div id="v"><canvas style="width:${W}px;height:${H}px"></canvas></div>
<script type="module">
import { Viewer } from "/openlime/Viewer.js";
import { Layer } from "/openlime/Layer.js";
import "/openlime/LayerRTI.js";
const viewer = new Viewer("#v", { canvas: { preserveDrawingBuffer: true } });
const layer = new Layer({ type: "rti", url: "/export/info.json", layout: "image",
                          normals: false });
viewer.addLayer("rti", layer);
const cv = document.querySelector("#v canvas");
const draw = () => new Promise((r) => { viewer.once("draw", r); viewer.redraw(); });
window.ready = (async () => {
  while (layer.tiles.get(0)?.missing !== 0) await new Promise((r) => setTimeout(r, 20));
  await draw();
})();
window.render = async (l) => {
  layer.setLight(l, 0);            // dt = 0: no animation (a missing dt leaves the light NaN)
  await draw();
  const c = document.createElement("canvas");
  c.width = cv.width; c.height = cv.height;
  const x = c.getContext("2d");
  x.drawImage(cv, 0, 0);
  return Array.from(x.getImageData(0, 0, c.width, c.height).data);
};
</script></body></html>`;

const requests = [], failed = [];
const server = http.createServer((req, resp) => {
  const u = decodeURIComponent(new URL(req.url, "http://x").pathname);
  requests.push(u);
  let f = null;
  if (u === "/" || u === "/index.html") {
    resp.writeHead(200, { "Content-Type": "text/html" });
    resp.end(PAGE);
    return;
  }
  if (u.startsWith("/openlime/")) {
    f = path.join(srcDir, u.slice("/openlime/".length));
    // OpenLIME imports a few modules without ".js" (Layout.js, Transform.js): a bundler
    // resolves them; a static server must too
    if (!fs.existsSync(f) && fs.existsSync(f + ".js")) f += ".js";
  } else if (u.startsWith("/export/")) {
    f = path.join(exportDir, u.slice("/export/".length));
  }
  if (!f || !fs.existsSync(f) || fs.statSync(f).isDirectory()) {
    failed.push(`404 ${u}`);
    resp.writeHead(404);
    resp.end();
    return;
  }
  resp.writeHead(200, { "Content-Type": TYPES[path.extname(f)] || "application/octet-stream" });
  fs.createReadStream(f).pipe(resp);
});
await new Promise((r) => server.listen(0, "127.0.0.1", r));
const port = server.address().port;

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"],
});
try {
  const page = await browser.newPage({ viewport: { width: W + 20, height: H + 20 },
                                       deviceScaleFactor: 1 });
  page.on("pageerror", (e) => failed.push(`page error: ${e}`));
  page.on("requestfailed", (r) => failed.push(`request failed: ${r.url()}`));
  page.on("console", (m) => { if (m.type() === "error") failed.push(`console: ${m.text()}`); });
  await page.goto(`http://127.0.0.1:${port}/index.html`);
  // the timer is unref'd: a pending one kept node alive for its whole 60 s after the run
  // (every run took 61 s for a second of work, until 2026-12-07)
  await Promise.race([page.evaluate(() => window.ready),
                      new Promise((_, rej) => setTimeout(() => rej(new Error(
                        "OpenLIME did not load the planes in 60 s")), 60000).unref())]);
  for (const [i, s] of lights.entries()) {
    const l = s.split(",").map(Number);
    const px = await page.evaluate((l) => window.render(l), l);
    const file = `${prefix}_${i}.rgba`;
    fs.writeFileSync(file, Buffer.from(px));
    console.log(JSON.stringify({ light: l, rgba: file, width: W, height: H }));
  }
} catch (e) {
  failed.push(String(e));
} finally {
  await browser.close();
  server.close();
}
console.log(JSON.stringify({ requests, failed }));
if (failed.length) process.exitCode = 1;
