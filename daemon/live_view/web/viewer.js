// The live view page: speaks the Foxglove WebSocket protocol (foxglove.websocket.v1) to
// the stereod that served it, and draws what the robot sees.
import * as THREE from "/three/build/three.module.js";
import { OrbitControls } from "/three/examples/jsm/controls/OrbitControls.js";
import { readImage, readPointCloud2 } from "./cdr.js";

const topics = ["/stereo/left/image_rect", "/stereo/depth", "/stereo/confidence",
                "/stereo/points", "/stereo/nearest", "/stereo/status"];
const $ = (id) => document.getElementById(id);
const state = { region: null, depth: null, confidence: null, reading: null, readingAt: 0 };

// Depth to colour: near red, far blue, over 0.3..10 m on a log scale.
function colour(z) {
  const t = Math.min(1, Math.max(0, Math.log(z / 0.3) / Math.log(10 / 0.3)));
  return [255 * (1 - t), 255 * (1 - Math.abs(2 * t - 1)), 255 * t];
}

function drawGrey(canvas, image) {
  canvas.width = image.width; canvas.height = image.height;
  const ctx = canvas.getContext("2d");
  const out = ctx.createImageData(image.width, image.height);
  for (let i = 0; i < image.width * image.height; ++i) {
    const v = image.data[i];
    out.data.set([v, v, v, 255], 4 * i);
  }
  ctx.putImageData(out, 0, 0);
  if (state.region) {
    const r = state.region;
    ctx.strokeStyle = "#ff0"; ctx.lineWidth = 2;
    ctx.strokeRect(r.x * image.width, r.y * image.height, r.width * image.width, r.height * image.height);
  }
}

function drawDepth(canvas, image) {
  canvas.width = image.width; canvas.height = image.height;
  const floats = new Float32Array(image.data.buffer.slice(image.data.byteOffset,
                                                          image.data.byteOffset + image.data.byteLength));
  state.depth = { width: image.width, height: image.height, values: floats };
  const ctx = canvas.getContext("2d");
  const out = ctx.createImageData(image.width, image.height);
  for (let i = 0; i < floats.length; ++i) {
    const z = floats[i];
    const [r, g, b] = Number.isNaN(z) ? [0, 0, 0] : colour(z);
    out.data.set([r, g, b, 255], 4 * i);
  }
  ctx.putImageData(out, 0, 0);
}

function showReading(reading) {
  // Its age: how old it was when sent (age_ms), plus the time since it arrived.
  state.reading = reading;
  state.readingAt = performance.now() - (reading.age_ms ?? 0);
  const el = $("distance");
  if (reading.valid) {
    el.textContent = `${reading.distance_m.toFixed(3)} m`;
    el.className = "";
  } else {
    const reason = reading.reason || {};
    el.textContent = `NO READING: ${reason.code || "unknown"}` +
                     (reason.message ? ` (${reason.message})` : "");
    el.className = "none";
  }
}

function showStatus(status) {
  const p = status.pipeline || {};
  if (p.region) state.region = p.region;
  const s = status.source || {};
  const stages = p.stage_ms ? Object.entries(p.stage_ms).map(([k, v]) => `${k} ${v} ms`).join(", ") : "";
  const cameras = (s.cameras || []).map((c) => `  ${c.name}: ${c.state}, ${c.fps} fps, ${c.dropped} dropped`).join("\n");
  $("status").textContent =
    `state ${status.state}, up ${status.uptime_s} s\n` +
    `pipeline ${p.fps} fps (${p.matcher}), ${stages}\n` +
    `latency (capture to result) p50 ${(p.latency_ms || {}).p50} ms, p99 ${(p.latency_ms || {}).p99} ms\n` +
    `source ${s.kind} ${s.state}, pairs ${s.pairs}, ring drops ${s.ring_dropped}\n${cameras}`;
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
    for (let i = 0; i < n; ++i) {
      const o = i * cloud.pointStep;
      positions[3 * i] = view.getFloat32(o, true);
      positions[3 * i + 1] = view.getFloat32(o + 4, true);
      positions[3 * i + 2] = view.getFloat32(o + 8, true);
      const v = view.getFloat32(o + 12, true) / 255;
      colours.set([v, v, v], 3 * i);
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

setInterval(() => {
  if (state.reading) $("age").textContent = `age ${((performance.now() - state.readingAt) / 1000).toFixed(2)} s`;
}, 200);

function connect() {
  const ws = new WebSocket(`ws://${location.host}/`, "foxglove.websocket.v1");
  ws.binaryType = "arraybuffer";
  const channels = new Map(); // subscription id -> topic
  ws.onopen = () => { $("connection").textContent = `connected to ${location.host}`; };
  ws.onclose = () => {
    $("connection").textContent = "disconnected; retrying…";
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
    if (topic === "/stereo/left/image_rect") drawGrey($("left"), readImage(payload));
    else if (topic === "/stereo/depth") drawDepth($("depth"), readImage(payload));
    else if (topic === "/stereo/confidence") state.confidence = readImage(payload);
    else if (topic === "/stereo/points") cloudView(readPointCloud2(payload));
    else if (topic === "/stereo/nearest") showReading(JSON.parse(new TextDecoder().decode(payload)));
    else if (topic === "/stereo/status") showStatus(JSON.parse(new TextDecoder().decode(payload)));
  };
}
connect();
