// Connects to stereod's live view with Foxglove's own client (@foxglove/ws-protocol),
// subscribes to every advertised channel for a while, decodes the CDR messages with
// @foxglove/rosmsg2-serialization, and prints what it saw as JSON:
//   node client.mjs ws://127.0.0.1:8765/?token=TOKEN SECONDS
// Latency is the client's wall clock (CLOCK_REALTIME, the time base of the live view's
// log times and header stamps) at receipt minus the message's log time; `clock_offset_ns`
// is the wall clock minus CLOCK_MONOTONIC (process.hrtime) here, to hold readings'
// stamp_realtime_ns against their stamp_ns.
import wsProtocol from "@foxglove/ws-protocol";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const [url, seconds] = [process.argv[2], Number(process.argv[3] ?? 5)];
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // channel id -> channel
const subscriptions = new Map(); // subscription id -> channel
const readers = new Map(); // channel id -> MessageReader
const seen = {}; // topic -> {count, bytes, latencies}
const out = { channels: [], counts: {}, bytes: {}, latency_ms: {}, statuses: [] };
// CLOCK_REALTIME now, in ns (performance.timeOrigin is the wall clock at the process start).
const wallNs = () => BigInt(Math.round((performance.timeOrigin + performance.now()) * 1e6));
out.clock_offset_ns = (wallNs() - process.hrtime.bigint()).toString();
let depth = null;
let nearest = null;
let status = null;
let zones = null;

client.on("advertise", (list) => {
  for (const channel of list) {
    channels.set(channel.id, channel);
    out.channels.push({ topic: channel.topic, encoding: channel.encoding,
                        schemaName: channel.schemaName, schemaEncoding: channel.schemaEncoding,
                        schemaLength: channel.schema.length });
    if (channel.encoding === "cdr") {
      readers.set(channel.id, new MessageReader(parse(channel.schema, { ros2: true })));
    }
    subscriptions.set(client.subscribe(channel.id), channel);
  }
});
client.on("status", (s) => out.statuses.push(s));
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const channel = subscriptions.get(subscriptionId);
  if (!channel) return;
  const now = wallNs();
  const entry = (seen[channel.topic] ??= { count: 0, bytes: 0, latencies: [] });
  entry.count += 1;
  entry.bytes += data.byteLength;
  entry.latencies.push(Number(now - timestamp) / 1e6);
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  if (channel.topic === "/stereo/depth" && depth === null) {
    const m = readers.get(channel.id).readMessage(bytes);
    const floats = new Float32Array(m.data.buffer.slice(m.data.byteOffset, m.data.byteOffset + m.data.byteLength));
    depth = { logTime: timestamp.toString(), encoding: m.encoding, width: m.width, height: m.height,
              step: m.step, frame_id: m.header.frame_id,
              stamp_ns: (BigInt(m.header.stamp.sec) * 1000000000n + BigInt(m.header.stamp.nanosec)).toString(),
              data: Array.from(floats, (v) => (Number.isNaN(v) ? null : v)) };
  } else if (channel.topic === "/stereo/left/image_rect" && out.left === undefined) {
    const m = readers.get(channel.id).readMessage(bytes);
    out.left = { encoding: m.encoding, width: m.width, height: m.height, step: m.step,
                 bytes: m.data.byteLength };
  } else if (channel.topic === "/stereo/points" && out.points === undefined) {
    const m = readers.get(channel.id).readMessage(bytes);
    out.points = { fields: m.fields.map((f) => ({ name: f.name, offset: f.offset, datatype: f.datatype })),
                   point_step: m.point_step, width: m.width, bytes: m.data.byteLength };
  } else if (readers.has(channel.id)) {
    readers.get(channel.id).readMessage(bytes); // every CDR message must decode
  } else if (channel.topic === "/stereo/nearest") {
    // As text too: stamp_realtime_ns (about 1.8e18) is beyond what a JavaScript number
    // holds exactly.
    out.nearest_text = new TextDecoder().decode(bytes);
    nearest = JSON.parse(out.nearest_text);
    out.nearest_log_time = timestamp.toString();
  } else if (channel.topic === "/stereo/status") {
    status = JSON.parse(new TextDecoder().decode(bytes));
  } else if (channel.topic === "/stereo/zones") {
    zones = JSON.parse(new TextDecoder().decode(bytes));
  }
});
client.on("error", (e) => { console.error(String(e)); process.exit(1); });

setTimeout(() => {
  for (const [topic, e] of Object.entries(seen)) {
    e.latencies.sort((a, b) => a - b);
    out.counts[topic] = e.count;
    out.bytes[topic] = e.bytes;
    out.latency_ms[topic] = { p50: e.latencies[Math.floor(e.latencies.length / 2)],
                              max: e.latencies[e.latencies.length - 1] };
  }
  out.seconds = seconds;
  out.depth = depth;
  out.nearest = nearest;
  out.status = status;
  out.zones = zones;
  client.close();
  // Exit once stdout is written: a pipe takes 64 KiB at a time.
  process.stdout.write(JSON.stringify(out) + "\n", () => process.exit(0));
}, seconds * 1000);
