// Opens stereod's live view page in Debian's Chromium (headless, through playwright-core),
// waits for the distance, hovers the depth image, and prints what the page shows as JSON;
// saves a screenshot:
//   node page.mjs http://127.0.0.1:8765/?token=TOKEN OUT.png
import { chromium } from "playwright-core";

const [url, screenshot] = [process.argv[2], process.argv[3]];
const browser = await chromium.launch({
  executablePath: process.env.STEREOD_CHROMIUM ?? "/usr/bin/chromium",
  args: ["--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader"],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 1000 } });
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(url);
  // The distance, or NO READING, and a drawn depth image.
  await page.waitForFunction(() => {
    const text = document.getElementById("distance").textContent;
    return / m$/.test(text) || text.startsWith("NO READING");
  }, null, { timeout: 30000 });
  await page.waitForFunction(() => document.getElementById("status").textContent.startsWith("state"),
                             null, { timeout: 30000 });
  await page.waitForTimeout(500);
  const shown = await page.evaluate(() => {
    const canvas = document.getElementById("depth");
    const pixels = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
    let sum = 0, sum2 = 0;
    const n = pixels.length / 4;
    for (let i = 0; i < pixels.length; i += 4) {
      const v = pixels[i] + pixels[i + 1] + pixels[i + 2];
      sum += v; sum2 += v * v;
    }
    const mean = sum / n;
    return { distance: document.getElementById("distance").textContent,
             depth_width: canvas.width, depth_height: canvas.height,
             depth_variance: sum2 / n - mean * mean,
             status: document.getElementById("status").textContent };
  });
  // Hovering the depth image below its centre shows that pixel's depth and confidence.
  const box = await page.locator("#depth").boundingBox();
  await page.mouse.move(box.x + box.width * 0.5, box.y + box.height * 0.6);
  await page.waitForFunction(() => document.getElementById("hover").style.display === "block",
                             null, { timeout: 5000 });
  const hover = await page.evaluate(() => document.getElementById("hover").textContent);
  await page.screenshot({ path: screenshot });
  process.stdout.write(JSON.stringify({ ...shown, hover, errors }) + "\n");
} finally {
  await browser.close();
}
