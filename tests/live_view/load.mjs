// Load on stereod's live view: CLIENTS of Foxglove's own client, each subscribed to every
// channel and reading all it is sent, plus one client that subscribes to every channel and
// then never reads (its socket paused). After SECONDS it prints, as JSON, what each reader
// received per topic, the readings' transit (their age at receipt, by CLOCK_MONOTONIC as
// the service's stamp_ns, minus their age_ms when the service wrote them: the time spent
// in the live view and on the way; p50 and max, ms), and whether the server closed the one
// that never read.
//   node load.mjs ws://127.0.0.1:8765/?token=TOKEN CLIENTS SECONDS
import net from "node:net";
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
const decoder = new TextDecoder();
const [url, clientCount, seconds] = [process.argv[2], Number(process.argv[3] ?? 8),
                                     Number(process.argv[4] ?? 30)];

function reader() {
  const client = new FoxgloveClient({ ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
  const topics = new Map(); // subscription id -> topic
  const seen = { counts: {}, bytes: 0, closed: false }; // closed: by the server, before the end
  const transits = [];
  client.on("advertise", (list) => {
    for (const channel of list) topics.set(client.subscribe(channel.id), channel.topic);
  });
  client.on("message", ({ subscriptionId, data }) => {
    const topic = topics.get(subscriptionId);
    seen.counts[topic] = (seen.counts[topic] ?? 0) + 1;
    seen.bytes += data.byteLength;
    if (topic === "/stereo/nearest") {
      const now = process.hrtime.bigint();
      const reading = JSON.parse(decoder.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)));
      if (reading.stamp_ns !== undefined) {
        transits.push(Number(now - BigInt(reading.stamp_ns)) / 1e6 - reading.age_ms);
      }
    }
  });
  client.on("close", () => { seen.closed = true; });
  client.on("error", (e) => console.error(`reader: ${e}`));
  return { client, seen, transits };
}

// The client that never reads, by hand: the handshake, the advertise it waits for, one
// masked subscribe frame for every channel, then no more reading.
function stuckClient() {
  const { hostname, port, pathname, search } = new URL(url);
  const socket = net.connect(Number(port), hostname);
  const state = { subscribed: false, closed: false, bytesRead: 0 };
  let received = Buffer.alloc(0);
  socket.on("connect", () => {
    socket.write(`GET ${pathname}${search} HTTP/1.1\r\nHost: ${hostname}:${port}\r\n` +
                 "Upgrade: websocket\r\nConnection: Upgrade\r\n" +
                 "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n" +
                 `Sec-WebSocket-Protocol: ${FoxgloveClient.SUPPORTED_SUBPROTOCOL}\r\n\r\n`);
  });
  socket.on("data", (chunk) => {
    state.bytesRead += chunk.length;
    if (state.subscribed) return;
    received = Buffer.concat([received, chunk]);
    const text = received.toString("latin1");
    if (!text.includes('"op":"advertise"')) return;
    // The channel ids of the advertise message (serverInfo, before it, has none).
    const ids = [...text.matchAll(/"id":(\d+)/g)].map((m) => Number(m[1]));
    const request = Buffer.from(JSON.stringify({
      op: "subscribe", subscriptions: ids.map((id) => ({ id, channelId: id })) }));
    const header = request.length < 126 ? Buffer.from([0x81, 0x80 | request.length])
                                        : Buffer.from([0x81, 0x80 | 126, request.length >> 8, request.length & 0xff]);
    const mask = Buffer.from([1, 2, 3, 4]);
    socket.write(Buffer.concat([header, mask, request.map((b, i) => b ^ mask[i % 4])]));
    state.subscribed = true;
    socket.pause();
  });
  socket.on("close", () => { state.closed = true; });
  socket.on("error", () => { state.closed = true; });
  return { socket, state };
}

const readers = Array.from({ length: clientCount }, reader);
const stuck = stuckClient();

setTimeout(() => {
  const out = { seconds, stuck: stuck.state, readers: readers.map((r) => {
    const seen = structuredClone(r.seen);
    const t = [...r.transits].sort((a, b) => a - b);
    seen.transit_ms = { p50: t[Math.floor(t.length / 2)] ?? null, max: t[t.length - 1] ?? null };
    return seen;
  }) };
  for (const r of readers) r.client.close();
  // What the server sent the stuck client before closing it is read now; a closed
  // connection then ends within moments.
  stuck.socket.resume();
  setTimeout(() => {
    stuck.socket.destroy();
    process.stdout.write(JSON.stringify(out) + "\n", () => process.exit(0));
  }, 3000);
}, seconds * 1000);
