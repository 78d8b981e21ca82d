// Reads a cut MCAP (a recording killed mid-way) record by record with @mcap/core's
// streaming reader, CRCs checked, and counts the messages per topic it yields before the
// file ends. Prints one JSON object.
//
//   node read_truncated.mjs FILE.mcap
import { readFile } from "node:fs/promises";
import { McapStreamReader } from "@mcap/core";
import { decompressHandlers, emit } from "./common.mjs";

const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
stream.append(await readFile(process.argv[2]));
const topics = new Map();
const counts = {};
let error = null;
try {
  let record;
  while ((record = stream.nextRecord())) {
    if (record.type === "Channel") topics.set(record.id, record.topic);
    if (record.type === "Message") {
      const topic = topics.get(record.channelId);
      counts[topic] = (counts[topic] ?? 0) + 1;
    }
  }
} catch (e) {
  error = String(e.message ?? e);
}
emit({ counts, done: stream.done(), bytesRemaining: stream.bytesRemaining(), error });
