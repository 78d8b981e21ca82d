// Reads a bag recorded by `stereoctl record --with depth,points` with @mcap/core and
// decodes, with @foxglove/rosmsg2-serialization, the /stereo/depth and /stereo/points
// messages whose header stamp is the given one (the pair's left image stamp). Prints one
// JSON object: the message count of each topic, and for each of the two messages its log
// time, header, layout fields and data as float32 values (NaN printed as null); a cloud
// with an `rgb` field also gets `rgb`, each point's field read as the uint32 0x00RRGGBB
// that ROS packs into it.
//
//   node read_results.mjs FILE.mcap STAMP_NS
import { McapIndexedReader } from "@mcap/core";
import { decompressHandlers, emit, fileReadable, messageReader } from "./common.mjs";

const [path, stampText] = process.argv.slice(2);
const stamp = BigInt(stampText);
const readable = await fileReadable(path);
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });

const readers = new Map();
for (const [id, channel] of reader.channelsById) {
  const schema = reader.schemasById.get(channel.schemaId);
  readers.set(id, messageReader(new TextDecoder().decode(schema.data)));
}

const found = {};
const counts = {};
for await (const message of reader.readMessages({ topics: ["/stereo/depth", "/stereo/points"] })) {
  const topic = reader.channelsById.get(message.channelId).topic;
  counts[topic] = (counts[topic] ?? 0) + 1;
  const decoded = readers.get(message.channelId).readMessage(message.data);
  const headerNs = BigInt(decoded.header.stamp.sec) * 1000000000n + BigInt(decoded.header.stamp.nanosec);
  if (headerNs !== stamp || found[topic] !== undefined) continue;
  // Both carry float32 only (32FC1; x, y, z, intensity, rgb): the values, little-endian.
  const bytes = Uint8Array.from(decoded.data);
  decoded.data = Array.from(new Float32Array(bytes.buffer));
  const rgb = (decoded.fields ?? []).find((field) => field.name === "rgb");
  if (rgb !== undefined) {
    const view = new DataView(bytes.buffer);
    decoded.rgb = [];
    for (let at = rgb.offset; at + 4 <= bytes.length; at += decoded.point_step)
      decoded.rgb.push(view.getUint32(at, true));
  }
  found[topic] = { logTime: message.logTime, message: decoded };
}
await readable.handle.close();
emit({ counts, depth: found["/stereo/depth"] ?? null, points: found["/stereo/points"] ?? null });
