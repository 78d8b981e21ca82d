// The live view page: speaks the Foxglove WebSocket protocol (foxglove.websocket.v1) to
// the stereod that served it, and draws what the robot sees. The reading is the first
// thing on the page and says its state at a glance (reading_view.js): a distance, a
// suspect calibration, something nearer than the range, no reading and why, or STALE once
// it is older than the service's max_reading_age_ms.
import * as THREE from "/three/build/three.module.js";
import { OrbitControls } from "/three/examples/jsm/controls/OrbitControls.js";
import { readImage, readPointCloud2 } from "./cdr.js";
import { colourBarTicks, jet, level, metres, percentileRange } from "./depth_colours.js";
import { readingView } from "./reading_view.js";

const topics = ["/stereo/left/image_rect", "/stereo/depth", "/stereo/confidence",
                "/stereo/points", "/stereo/nearest", "/stereo/status", "/stereo/zones"];
const $ = (id) => document.getElementById(id);
const state = {
  region: null, depth: null, confidence: null,
  reading: null, readingAt: 0, // the reading, and when it was taken by the page's clock
  maxAgeMs: 1000,              // publish.max_reading_age_ms, from the status
  connected: false,
  range: null,                 // the depth colours' range in force, {near, far} metres
};

// The left image: mono8, or rgb8 where the left camera has colour (rows `step` bytes).
function drawGrey(canvas, image) {
  canvas.width = image.width; canvas.height = image.height;
  const ctx = canvas.getContext("2d");
  const out = ctx.createImageData(image.width, image.height);
  const rgb = image.encoding === "rgb8";
  for (let y = 0; y < image.height; ++y) {
    for (let x = 0; x < image.width; ++x) {
      const i = y * image.width + x;
      const at = y * image.step + (rgb ? 3 * x : x);
      out.data[4 * i] = image.data[at];
      out.data[4 * i + 1] = image.data[rgb ? at + 1 : at];
      out.data[4 * i + 2] = image.data[rgb ? at + 2 : at];
      out.data[4 * i + 3] = 255;
    }
  }
  ctx.putImageData(out, 0, 0);
  if (state.region) {
    const r = state.region;
    ctx.strokeStyle = "#ff0"; ctx.lineWidth = 2;
    ctx.strokeRect(r.x * image.width, r.y * image.height, r.width * image.width, r.height * image.height);
  }
}

// The range the depth colours follow: the frame's own (percentiles), or the fixed one.
function colourRange(values) {
  if ($("range-mode").value === "fixed") {
    const near = Number($("range-near").value), far = Number($("range-far").value);
    if (near > 0 && far > near) return { near, far };
  }
  return percentileRange(values) ?? { near: 1, far: 10 };
}

function drawDepth() {
  const d = state.depth;
  if (!d) return;
  const canvas = $("depth");
  canvas.width = d.width; canvas.height = d.height;
  const range = colourRange(d.values);
  state.range = range;
  const ctx = canvas.getContext("2d");
  const out = ctx.createImageData(d.width, d.height);
  const pixels = out.data;
  for (let i = 0; i < d.values.length; ++i) {
    const z = d.values[i];
    const o = 4 * i;
    pixels[o + 3] = 255;
    if (!(z > 0)) continue; // NaN: no depth, black
    const [r, g, b] = jet(level(z, range.near, range.far));
    pixels[o] = r; pixels[o + 1] = g; pixels[o + 2] = b;
  }
  ctx.putImageData(out, 0, 0);
  drawColourBar(range);
}

// The colour bar under the depth image: far (blue) on the left to near (red) on the
// right, as the colours spread (inverse depth), with ticks in metres.
function drawColourBar(range) {
  const canvas = $("colourbar");
  const width = canvas.clientWidth || canvas.width;
  canvas.width = width;
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, width, canvas.height);
  for (let x = 0; x < width; ++x) {
    const [r, g, b] = jet(x / (width - 1));
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.fillRect(x, 0, 1, 16);
  }
  ctx.fillStyle = "#ccc"; ctx.strokeStyle = "#ccc";
  ctx.font = "12px system-ui, sans-serif";
  const labels = [];
  for (const tick of colourBarTicks(range.near, range.far)) {
    const x = Math.round(tick.position * (width - 1));
    ctx.fillRect(x, 16, 1, 5);
    const text = metres(tick.depth_m);
    const w = ctx.measureText(text).width;
    ctx.fillText(text, Math.min(width - w, Math.max(0, x - w / 2)), 34);
    labels.push(text);
  }
  canvas.dataset.labels = labels.join(" ");
}

function showReading() {
  const ageMs = state.reading ? performance.now() - state.readingAt : 0;
  const view = readingView(state.reading, ageMs, state.maxAgeMs, state.connected);
  const el = $("reading");
  el.dataset.state = view.state;
  $("distance").textContent = view.text;
  $("detail").textContent = view.detail;
  $("age").textContent = state.reading && state.reading.age_ms !== undefined
    ? `age ${(ageMs / 1000).toFixed(2)} s` : "";
}

function takeReading(reading) {
  // Its age: how old it was when sent (age_ms), plus the time since it arrived.
  state.reading = reading;
  state.readingAt = performance.now() - (reading.age_ms ?? 0);
  showReading();
}

function showStatus(status) {
  const p = status.pipeline || {};
  if (p.region) state.region = p.region;
  if (typeof status.max_reading_age_ms === "number") state.maxAgeMs = status.max_reading_age_ms;
  const s = status.source || {};
  const stages = p.stage_ms ? Object.entries(p.stage_ms).map(([k, v]) => `${k} ${v} ms`).join(", ") : "";
  const cameras = (s.cameras || []).map((c) => `  ${c.name}: ${c.state}, ${c.fps} fps, ${c.dropped} dropped`).join("\n");
  const live = status.live_view || {};
  $("status").textContent =
    `state ${status.state}, up ${status.uptime_s} s\n` +
    `pipeline ${p.fps} fps (${p.matcher}), ${stages}\n` +
    `latency (capture to result) p50 ${(p.latency_ms || {}).p50} ms, p99 ${(p.latency_ms || {}).p99} ms\n` +
    `source ${s.kind} ${s.state}, pairs ${s.pairs}, ring drops ${s.ring_dropped}\n${cameras}\n` +
    `live view: ${live.clients} clients, ${live.readings_sent} readings sent, ` +
    `${live.frames_dropped} frames dropped for slow clients`;
  const health = status.calibration_health || {};
  const healthEl = $("health");
  healthEl.dataset.state = health.state || "unknown";
  let text = `calibration health: ${health.state || "unknown"}`;
  if (health.reason) text += ` (${health.reason})`;
  if (typeof health.row_offset_px === "number") {
    text += `, rows ${health.row_offset_px >= 0 ? "+" : ""}${health.row_offset_px.toFixed(2)} px apart` +
            (typeof health.row_offset_p90_px === "number" ? `, 90 % within ${health.row_offset_p90_px.toFixed(2)} px` : "") +
            (typeof health.matches === "number" ? `, ${health.matches} matches` : "");
  }
  healthEl.textContent = text;
}

function showZones(message) {
  const list = $("zones");
  list.replaceChildren();
  const zones = message.zones || [];
  if (zones.length === 0) {
    const item = document.createElement("li");
    item.textContent = "zones: none configured";
    list.appendChild(item);
    return;
  }
  for (const zone of zones) {
    const item = document.createElement("li");
    item.dataset.state = zone.state;
    let text = `zone ${zone.name}: ${zone.state}`;
    if (zone.reason) text += ` (${zone.reason})`;
    if (zone.points > 0 && typeof zone.nearest_m === "number") text += `, nearest ${zone.nearest_m.toFixed(3)} m`;
    text += `, ${zone.points} points, ${Math.round(100 * (zone.visible_fraction ?? 0))} % in sight`;
    item.textContent = text;
    list.appendChild(item);
  }
}

// The 3D view; without WebGL (a headless browser, an old GPU) the page works without it.
const cloudView = (() => {
  const el = $("cloud");
  try {
    return makeCloudView(el);
  } catch (error) {
    el.textContent = `no 3D view: ${error.message}`;
    return () => {};
  }
})();

function makeCloudView(el) {
  const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
  renderer.setSize(el.clientWidth, el.clientHeight);
  el.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(60, el.clientWidth / el.clientHeight, 0.01, 100);
  camera.position.set(0, 0, -0.5); // behind the stereo camera, looking along +z (optical frame)
  camera.up.set(0, -1, 0);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.set(0, 0, 2);
  controls.update();
  const geometry = new THREE.BufferGeometry();
  const material = new THREE.PointsMaterial({ size: 0.01, vertexColors: true });
  scene.add(new THREE.Points(geometry, material));
  (function frame() { renderer.render(scene, camera); requestAnimationFrame(frame); })();
  return (cloud) => {
    const n = cloud.width * cloud.height;
    const view = new DataView(cloud.data.buffer, cloud.data.byteOffset, cloud.data.byteLength);
    const positions = new Float32Array(3 * n);
    const colours = new Float32Array(3 * n);
    // Where the left camera has colour the points carry PCL's packed `rgb` (a float32
    // whose bits are 0x00RRGGBB); otherwise their grey `intensity`.
    const rgb = cloud.fields.find((f) => f.name === "rgb");
    const intensity = cloud.fields.find((f) => f.name === "intensity");
    for (let i = 0; i < n; ++i) {
      const o = i * cloud.pointStep;
      positions[3 * i] = view.getFloat32(o, true);
      positions[3 * i + 1] = view.getFloat32(o + 4, true);
      positions[3 * i + 2] = view.getFloat32(o + 8, true);
      if (rgb) {
        const packed = view.getUint32(o + rgb.offset, true);
        colours[3 * i] = ((packed >> 16) & 0xff) / 255;
        colours[3 * i + 1] = ((packed >> 8) & 0xff) / 255;
        colours[3 * i + 2] = (packed & 0xff) / 255;
      } else {
        const v = intensity ? view.getFloat32(o + intensity.offset, true) / 255 : 1;
        colours[3 * i] = v; colours[3 * i + 1] = v; colours[3 * i + 2] = v;
      }
    }
    geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute("color", new THREE.BufferAttribute(colours, 3));
  };
}

$("depth").addEventListener("mousemove", (event) => {
  const hover = $("hover");
  const d = state.depth;
  if (!d) return;
  const rect = event.target.getBoundingClientRect();
  const x = Math.floor((event.clientX - rect.left) / rect.width * d.width);
  const y = Math.floor((event.clientY - rect.top) / rect.height * d.height);
  const z = d.values[y * d.width + x];
  const c = state.confidence ? state.confidence.data[y * state.confidence.width + x] : undefined;
  hover.style.display = "block";
  hover.style.left = `${event.clientX - rect.left + 12}px`;
  hover.style.top = `${event.clientY - rect.top + 12}px`;
  hover.textContent = `(${x}, ${y}) ` + (Number.isNaN(z) ? "no depth" : `${z.toFixed(3)} m`) +
                      (c === undefined ? "" : `, confidence ${c}`);
});
$("depth").addEventListener("mouseleave", () => { $("hover").style.display = "none"; });
for (const id of ["range-mode", "range-near", "range-far"]) $(id).addEventListener("input", drawDepth);

// The reading's age and state move on with the clock, between messages too.
setInterval(showReading, 200);

function showConnection(connected, text) {
  state.connected = connected;
  const el = $("connection");
  el.dataset.connected = String(connected);
  el.textContent = text;
  showReading();
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/`, "foxglove.websocket.v1");
  ws.binaryType = "arraybuffer";
  const channels = new Map(); // subscription id -> topic
  ws.onopen = () => showConnection(true, `● connected to ${location.host}`);
  ws.onclose = () => {
    showConnection(false, "○ disconnected; retrying…");
    setTimeout(connect, 1000);
  };
  ws.onmessage = (event) => {
    if (typeof event.data === "string") {
      const message = JSON.parse(event.data);
      if (message.op === "advertise") {
        const subscriptions = [];
        for (const channel of message.channels) {
          if (!topics.includes(channel.topic)) continue;
          const id = subscriptions.length + 1;
          channels.set(id, channel.topic);
          subscriptions.push({ id, channelId: channel.id });
        }
        ws.send(JSON.stringify({ op: "subscribe", subscriptions }));
      }
      return;
    }
    const bytes = new Uint8Array(event.data);
    if (bytes[0] !== 1) return;
    const view = new DataView(event.data);
    const topic = channels.get(view.getUint32(1, true));
    const payload = bytes.subarray(13);
    const json = () => JSON.parse(new TextDecoder().decode(payload));
    if (topic === "/stereo/left/image_rect") drawGrey($("left"), readImage(payload));
    else if (topic === "/stereo/depth") {
      const image = readImage(payload);
      const floats = new Float32Array(image.data.buffer.slice(image.data.byteOffset,
                                                              image.data.byteOffset + image.data.byteLength));
      state.depth = { width: image.width, height: image.height, values: floats };
      drawDepth();
    } else if (topic === "/stereo/confidence") state.confidence = readImage(payload);
    else if (topic === "/stereo/points") cloudView(readPointCloud2(payload));
    else if (topic === "/stereo/nearest") takeReading(json());
    else if (topic === "/stereo/status") showStatus(json());
    else if (topic === "/stereo/zones") showZones(json());
  };
}
connect();
