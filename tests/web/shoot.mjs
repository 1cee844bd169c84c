// Open an exported RTI page in headless Chromium, move the mouse to each given point of the
// picture (fractions of its width and height), and screenshot the picture after each move.
// Prints one JSON line per point: {"x", "y", "light": [lx, ly, lz] (what the page set),
// "png": path}. Usage: node shoot.mjs PAGE.html OUT_PREFIX x1,y1 [x2,y2 ...]
import { chromium } from "playwright-core";
import { pathToFileURL } from "node:url";

const [page_path, prefix, ...points] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"],
});
try {
  const page = await browser.newPage({ viewport: { width: 900, height: 900 },
                                       deviceScaleFactor: 1 });
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(pathToFileURL(page_path).href);
  await page.waitForSelector("body[data-ready='1']", { timeout: 30000 });
  const canvas = page.locator("#rti-canvas");
  const box = await canvas.boundingBox();
  for (const [i, p] of points.entries()) {
    const [fx, fy] = p.split(",").map(Number);
    await page.mouse.move(box.x + fx * box.width, box.y + fy * box.height);
    const light = await page.evaluate(() => window.relightLight);
    const png = `${prefix}_${i}.png`;
    await canvas.screenshot({ path: png });
    console.log(JSON.stringify({ x: fx, y: fy, light, png, width: box.width,
                                 height: box.height }));
  }
  if (errors.length) { console.error(errors.join("\n")); process.exitCode = 1; }
} finally {
  await browser.close();
}
