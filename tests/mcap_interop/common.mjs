// What the interop scripts share: file access for @mcap/core, zstd for its readers, and
// ROS 2 message (de)serializers built from a schema's ros2msg text.
import { open } from "node:fs/promises";
import { decompress } from "fzstd";
import { parse } from "@foxglove/rosmsg";
import { MessageReader, MessageWriter } from "@foxglove/rosmsg2-serialization";

export const decompressHandlers = {
  zstd: (buffer, decompressedSize) => {
    const out = decompress(buffer);
    if (BigInt(out.length) !== decompressedSize) {
      throw new Error(`zstd chunk: ${out.length} bytes, expected ${decompressedSize}`);
    }
    return out;
  },
};

// IReadable over a file, for McapIndexedReader.
export async function fileReadable(path) {
  const handle = await open(path, "r");
  const { size } = await handle.stat();
  return {
    handle,
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      const { bytesRead } = await handle.read(buffer, 0, buffer.length, Number(offset));
      if (bytesRead !== buffer.length) throw new Error(`short read at ${offset}`);
      return buffer;
    },
  };
}

export function messageReader(schemaText) {
  return new MessageReader(parse(schemaText, { ros2: true }));
}

export function messageWriter(schemaText) {
  return new MessageWriter(parse(schemaText, { ros2: true }));
}

// Prints one JSON object (bigints as numbers or strings) for the C++ test to read.
export function emit(object) {
  process.stdout.write(
    JSON.stringify(object, (_, v) => (typeof v === "bigint" ? (v <= BigInt(Number.MAX_SAFE_INTEGER) ? Number(v) : v.toString()) : v)) + "\n",
  );
}
