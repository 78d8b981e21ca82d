// Reads an MCAP written by stereod with @mcap/core, twice: through its summary
// (McapIndexedReader) and record by record with every CRC checked (McapStreamReader).
// Decodes the first Image and CameraInfo of each topic with @foxglove/rosmsg2-serialization.
// Prints one JSON object: header, channels with their schemas and message counts,
// statistics, and the decoded messages (image pixels as base64).
//
//   node read_ours.mjs FILE.mcap
import { readFile } from "node:fs/promises";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { decompressHandlers, emit, fileReadable, messageReader } from "./common.mjs";

const path = process.argv[2];
const readable = await fileReadable(path);
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });

const channels = [];
const readers = new Map();
for (const [id, channel] of reader.channelsById) {
  const schema = reader.schemasById.get(channel.schemaId);
  const text = new TextDecoder().decode(schema.data);
  readers.set(id, messageReader(text));
  channels.push({
    id,
    topic: channel.topic,
    messageEncoding: channel.messageEncoding,
    schemaName: schema.name,
    schemaEncoding: schema.encoding,
    qos: channel.metadata.get("offered_qos_profiles") !== undefined,
    count: Number(reader.statistics?.channelMessageCounts.get(id) ?? -1),
  });
}

// Every message through the index, in log time order; the first of each topic decoded.
const counted = new Map();
const first = {};
let previous = -1n;
let ordered = true;
for await (const message of reader.readMessages()) {
  const channel = reader.channelsById.get(message.channelId);
  counted.set(channel.topic, (counted.get(channel.topic) ?? 0) + 1);
  if (message.logTime < previous) ordered = false;
  previous = message.logTime;
  if (first[channel.topic] === undefined) {
    const decoded = readers.get(message.channelId).readMessage(message.data);
    if (decoded.data instanceof Uint8Array) {
      decoded.data = Buffer.from(decoded.data).toString("base64");
    }
    for (const key of ["d", "k", "r", "p"]) {
      if (decoded[key] !== undefined) decoded[key] = Array.from(decoded[key]);
    }
    first[channel.topic] = { logTime: message.logTime, message: decoded };
  }
}
await readable.handle.close();

// The whole file record by record, CRCs checked (data section, chunks, summary).
const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
stream.append(await readFile(path));
const streamed = {};
let record;
while ((record = stream.nextRecord())) {
  streamed[record.type] = (streamed[record.type] ?? 0) + 1;
}

emit({
  profile: reader.header.profile,
  library: reader.header.library,
  chunks: reader.chunkIndexes.length,
  compression: [...new Set(reader.chunkIndexes.map((c) => c.compression))],
  messageCount: reader.statistics?.messageCount,
  channels,
  counted: Object.fromEntries(counted),
  ordered,
  first,
  streamDone: stream.done(),
  streamed,
});
