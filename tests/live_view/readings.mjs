// Counts the readings a Foxglove client gets from stereod's live view while it is
// subscribed to every channel (or to the topics named after SECONDS) and reads all it is
// sent: Foxglove's own client, decoding nothing but the JSON channels. After SECONDS it
// prints, as JSON, every /stereo/nearest message (the reading's frame, its age when it
// reached the client, and whether it was valid), the message count per topic, and
// whether the server closed the connection.
//   node readings.mjs ws://127.0.0.1:8765/?token=TOKEN SECONDS [TOPIC...]
// Age: the client's CLOCK_MONOTONIC at receipt (process.hrtime, the clock of stereod's
// `stamp_ns`) minus the reading's capture stamp; transit: that age minus the reading's own
// `age_ms`, its age when the service wrote it: the time it spent in the live view and on
// the way.
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
const [url, seconds] = [process.argv[2], Number(process.argv[3] ?? 10)];
const only = process.argv.slice(4);

const client = new FoxgloveClient({ ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
const topics = new Map(); // subscription id -> topic
const out = { seconds, counts: {}, bytes: 0, readings: [], closed: false };
const decoder = new TextDecoder();

client.on("advertise", (list) => {
  for (const channel of list) {
    if (only.length > 0 && !only.includes(channel.topic)) continue;
    topics.set(client.subscribe(channel.id), channel.topic);
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const now = process.hrtime.bigint();
  const topic = topics.get(subscriptionId);
  out.counts[topic] = (out.counts[topic] ?? 0) + 1;
  out.bytes += data.byteLength;
  if (topic !== "/stereo/nearest") return;
  const reading = JSON.parse(decoder.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)));
  const age_ms = reading.stamp_ns === undefined ? null : Number(now - BigInt(reading.stamp_ns)) / 1e6;
  const transit_ms = age_ms === null ? null : age_ms - reading.age_ms;
  out.readings.push({ frame: reading.frame, valid: reading.valid, age_ms, transit_ms });
});
client.on("close", () => { out.closed = true; });
client.on("error", (e) => console.error(`readings: ${e}`));

setTimeout(() => {
  const closed = out.closed;
  client.close();
  out.closed = closed;
  process.stdout.write(JSON.stringify(out) + "\n", () => process.exit(0));
}, seconds * 1000);
