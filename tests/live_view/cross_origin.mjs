// A web page of another origin trying the live view, as any site a developer visits
// could: serves a page on HOST (another loopback address, so another origin than the live
// view's) whose script opens each WebSocket URL given, subscribes to every channel it is
// advertised and counts what arrives; opens it in Debian's Chromium (headless, through
// playwright-core) and prints, as JSON, what each attempt got:
//   node cross_origin.mjs HOST WS_URL... SECONDS
// {"origin": "http://HOST:PORT", "attempts": [{"url", "opened", "messages", "closeCode"}]}
import http from "node:http";
import { chromium } from "playwright-core";

const args = process.argv.slice(2);
const host = args[0];
const seconds = Number(args[args.length - 1]);
const urls = args.slice(1, -1);

const script = `
window.results = ${JSON.stringify(urls)}.map((url) => {
  const r = { url, opened: false, messages: 0, closeCode: null };
  const ws = new WebSocket(url, "foxglove.websocket.v1");
  ws.binaryType = "arraybuffer";
  ws.onopen = () => { r.opened = true; };
  ws.onclose = (e) => { r.closeCode = e.code; };
  ws.onmessage = (e) => {
    if (typeof e.data === "string") {
      const m = JSON.parse(e.data);
      if (m.op === "advertise")
        ws.send(JSON.stringify({ op: "subscribe",
                                 subscriptions: m.channels.map((c) => ({ id: c.id, channelId: c.id })) }));
      return;
    }
    r.messages += 1;
  };
  return r;
});`;
const server = http.createServer((request, response) => {
  response.writeHead(200, { "Content-Type": "text/html" });
  response.end(`<!DOCTYPE html><title>elsewhere</title><script>${script}</script>`);
});
await new Promise((resolve) => server.listen(0, host, resolve));
const origin = `http://${host}:${server.address().port}`;

const browser = await chromium.launch({
  executablePath: process.env.STEREOD_CHROMIUM ?? "/usr/bin/chromium",
  args: ["--no-sandbox"],
});
try {
  const page = await browser.newPage();
  await page.goto(`${origin}/`);
  await page.waitForTimeout(seconds * 1000);
  const attempts = await page.evaluate(() => window.results);
  process.stdout.write(JSON.stringify({ origin, attempts }) + "\n");
} finally {
  await browser.close();
  server.close();
}
