// Opens stereod's live view page in Debian's Chromium (headless, through playwright-core)
// and follows it through the reading states named on the command line, in order
// (daemon/live_view/web/reading_view.js: valid, suspect, nearer, none, stale, ...). For
// each it waits until the page shows that state, saves a screenshot OUTDIR/NAME-STATE.png,
// and prints one JSON line with what the page shows; the caller may change the service
// between two states (stop it, say) and read the next line.
//   node page.mjs http://127.0.0.1:8765/?token=TOKEN OUTDIR NAME [STATE...]    (default: valid)
// With the first state a distance (valid or suspect), it also hovers the depth image and
// reports the hover text. Each state's line also says what the 3-D view drew (`cloud`).
import { mkdirSync } from "node:fs";
import { chromium } from "playwright-core";

const [url, outDir, name] = process.argv.slice(2, 5);
const states = process.argv.length > 5 ? process.argv.slice(5) : ["valid"];
mkdirSync(outDir, { recursive: true });
const browser = await chromium.launch({
  executablePath: process.env.STEREOD_CHROMIUM ?? "/usr/bin/chromium",
  args: ["--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader"],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 1000 } });
  const errors = [];
  const failed = []; // requests the server answered with an error (a favicon 404, ...)
  page.on("pageerror", (e) => errors.push(String(e)));
  page.on("response", (r) => { if (r.status() >= 400) failed.push(`${r.status()} ${r.url()}`); });
  // The 3-D view as drawn: its lit pixels (the background is black) and their mean chroma
  // (largest minus smallest channel: 0 for grey points).
  await page.addInitScript(() => {
    window.cloudDrawn = () => {
      const gl = document.getElementById("cloud").querySelector("canvas");
      const copy = document.createElement("canvas");
      copy.width = gl.width; copy.height = gl.height;
      const ctx = copy.getContext("2d");
      ctx.drawImage(gl, 0, 0);
      const px = ctx.getImageData(0, 0, copy.width, copy.height).data;
      let lit = 0, chroma = 0;
      for (let i = 0; i < px.length; i += 4) {
        const hi = Math.max(px[i], px[i + 1], px[i + 2]);
        if (hi <= 8) continue;
        ++lit;
        chroma += hi - Math.min(px[i], px[i + 1], px[i + 2]);
      }
      return { lit_pixels: lit, mean_chroma: lit ? chroma / lit : 0 };
    };
  });
  await page.goto(url);
  // The status panel filled: the page is connected and reads its channels.
  await page.waitForFunction(() => document.getElementById("status").textContent.startsWith("state"),
                             null, { timeout: 30000 });
  let first = true;
  for (const state of states) {
    if (state === "valid" || state === "suspect" || state === "none" || state === "nearer") {
      // A depth image drawn, and its colour bar.
      await page.waitForFunction(() => document.getElementById("colourbar").dataset.labels,
                                 null, { timeout: 30000 });
    }
    if (state === "valid" || state === "suspect") {
      // And a cloud drawn in the 3-D view.
      await page.waitForFunction(() => window.cloudDrawn().lit_pixels > 0, null,
                                 { timeout: 30000, polling: 100 });
    }
    // What the page shows is read in the same evaluation that finds it in the state: a
    // reading that ages into STALE a moment later must not be taken for the state asked.
    const found = await page.waitForFunction((s) => {
      const $ = (id) => document.getElementById(id);
      if ($("reading").dataset.state !== s) return false;
      const canvas = $("depth");
      const pixels = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
      let sum = 0, sum2 = 0;
      const n = pixels.length / 4;
      for (let i = 0; i < pixels.length; i += 4) {
        const v = pixels[i] + pixels[i + 1] + pixels[i + 2];
        sum += v; sum2 += v * v;
      }
      const mean = sum / n;
      return { state: $("reading").dataset.state, distance: $("distance").textContent,
               detail: $("detail").textContent, distance_colour: getComputedStyle($("distance")).color,
               age: $("age").textContent, connection: $("connection").textContent,
               connected: $("connection").dataset.connected,
               depth_width: canvas.width, depth_height: canvas.height,
               depth_variance: sum2 / n - mean * mean,
               colourbar: $("colourbar").dataset.labels ?? "",
               status: $("status").textContent, health: $("health").textContent,
               health_state: $("health").dataset.state,
               zones: [...$("zones").children].map((li) => ({ state: li.dataset.state, text: li.textContent })),
               cloud: window.cloudDrawn() };
    }, state, { timeout: 45000, polling: 20 });
    const shown = await found.jsonValue();
    if (first && (state === "valid" || state === "suspect")) {
      // Hovering the depth image below its centre shows that pixel's depth and confidence.
      const box = await page.locator("#depth").boundingBox();
      await page.mouse.move(box.x + box.width * 0.5, box.y + box.height * 0.6);
      await page.waitForFunction(() => document.getElementById("hover").style.display === "block",
                                 null, { timeout: 5000 });
      shown.hover = await page.evaluate(() => document.getElementById("hover").textContent);
      await page.mouse.move(0, 0);
    }
    first = false;
    shown.screenshot = `${outDir}/${name}-${state}.png`;
    await page.screenshot({ path: shown.screenshot });
    shown.errors = errors;
    shown.failed_requests = failed;
    await new Promise((done) => process.stdout.write(JSON.stringify(shown) + "\n", done));
  }
} finally {
  await browser.close();
}
