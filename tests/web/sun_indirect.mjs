// Open a sun-indirect export's page in headless Chromium, set each sun (azimuth, elevation in
// degrees) through the page's sunIndirectSet, and save the canvas's pixels (R*R*4 raw bytes).
// Usage: node sun_indirect.mjs PAGE.html OUT_PREFIX az1,el1 [az2,el2 ...]
// Prints one JSON line per sun: {"sun": [az, el], "rgba": path, "width", "height"}.
import { chromium } from "playwright-core";
import fs from "node:fs";
import { pathToFileURL } from "node:url";

const [pagePath, prefix, ...suns] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"],
});
const errors = [];
try {
  const page = await browser.newPage({ viewport: { width: 900, height: 900 },
                                       deviceScaleFactor: 1 });
  page.on("pageerror", (e) => errors.push(String(e)));
  page.on("console", (m) => { if (m.type() === "error") errors.push(m.text()); });
  await page.goto(pathToFileURL(pagePath).href);
  await page.waitForSelector("body[data-ready='1']", { timeout: 30000 });
  for (const [i, s] of suns.entries()) {
    const [az, el] = s.split(",").map(Number);
    const px = await page.evaluate(([az, el]) => {
      window.sunIndirectSet(az, el);
      const c = document.getElementById("si-canvas");
      const d = c.getContext("2d").getImageData(0, 0, c.width, c.height);
      return { w: c.width, h: c.height, data: Array.from(d.data) };
    }, [az, el]);
    const file = `${prefix}_${i}.rgba`;
    fs.writeFileSync(file, Buffer.from(px.data));
    console.log(JSON.stringify({ sun: [az, el], rgba: file, width: px.w, height: px.h }));
  }
} finally {
  await browser.close();
}
if (errors.length) { console.error(errors.join("\n")); process.exitCode = 1; }
