// Writes a ROS 2 bag with @mcap/core's writer and @foxglove/rosmsg2-serialization, as a
// robot's recorder would: images of a stereo pair on topics of its own naming, their
// camera_info, and an unrelated third image topic. The pixels come from PGM files.
//
//   node write_bag.mjs OUT.mcap SPEC.json
// SPEC: { "left_topic", "right_topic", "other_topic", "compress": bool,
//         "pairs": [{ "left": PGM, "right": PGM, "left_stamp_ns", "right_stamp_ns" }],
//         "left_info": {k, d, r, p, ...} | null, "right_info": ... }
import { open, readFile } from "node:fs/promises";
import { McapWriter } from "@mcap/core";
import { emit, messageWriter } from "./common.mjs";

const [out, specPath] = process.argv.slice(2);
const spec = JSON.parse(await readFile(specPath, "utf8"));

const SEP = "=".repeat(80) + "\n";
const HEADER = `${SEP}MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n${SEP}MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n`;
const IMAGE = `std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n${HEADER}`;
const INFO = `std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nRegionOfInterest roi\n${SEP}MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n${HEADER}`;

// Binary PGM (P5, 8-bit).
async function readPgm(path) {
  const bytes = await readFile(path);
  const text = bytes.subarray(0, 64).toString("latin1");
  const m = /^P5\s+(\d+)\s+(\d+)\s+(\d+)\s/.exec(text);
  if (!m || m[3] !== "255") throw new Error(`${path}: not an 8-bit binary PGM`);
  const [width, height] = [Number(m[1]), Number(m[2])];
  return { width, height, data: bytes.subarray(m[0].length, m[0].length + width * height) };
}

const handle = await open(out, "w");
let position = 0n;
const writable = {
  write: async (buffer) => {
    await handle.write(buffer);
    position += BigInt(buffer.byteLength);
  },
  position: () => position,
};
const writer = new McapWriter({ writable, chunkSize: 256 * 1024 });
await writer.start({ profile: "ros2", library: "@mcap/core interop test" });
const enc = new TextEncoder();
const imageSchema = await writer.registerSchema({ name: "sensor_msgs/msg/Image", encoding: "ros2msg", data: enc.encode(IMAGE) });
const infoSchema = await writer.registerSchema({ name: "sensor_msgs/msg/CameraInfo", encoding: "ros2msg", data: enc.encode(INFO) });
const qos = new Map([["offered_qos_profiles", ""]]);
const channel = (topic, schemaId) => writer.registerChannel({ topic, schemaId, messageEncoding: "cdr", metadata: qos });
const other = await channel(spec.other_topic, imageSchema);
const left = await channel(spec.left_topic, imageSchema);
const right = await channel(spec.right_topic, imageSchema);
const infoTopic = (t) => t.slice(0, t.lastIndexOf("/") + 1) + "camera_info";
const leftInfo = spec.left_info ? await channel(infoTopic(spec.left_topic), infoSchema) : null;
const rightInfo = spec.right_info ? await channel(infoTopic(spec.right_topic), infoSchema) : null;

const imageWriter = messageWriter(IMAGE);
const infoWriter = messageWriter(INFO);
const stamp = (ns) => ({ sec: Number(BigInt(ns) / 1000000000n), nanosec: Number(BigInt(ns) % 1000000000n) });
let sequence = 0;
async function add(channelId, ns, message, writer_) {
  await writer.addMessage({ channelId, sequence: sequence++, logTime: BigInt(ns), publishTime: BigInt(ns), data: writer_.writeMessage(message) });
}
function image(pgm, ns, frame) {
  return { header: { stamp: stamp(ns), frame_id: frame }, height: pgm.height, width: pgm.width, encoding: "mono8", is_bigendian: 0, step: pgm.width, data: pgm.data };
}
function info(i, ns, frame) {
  return { header: { stamp: stamp(ns), frame_id: frame }, height: i.height, width: i.width, distortion_model: i.distortion_model, d: i.d, k: i.k, r: i.r, p: i.p, binning_x: 0, binning_y: 0, roi: { x_offset: 0, y_offset: 0, height: 0, width: 0, do_rectify: false } };
}
let written = 0;
for (const pair of spec.pairs) {
  const l = await readPgm(pair.left);
  const r = await readPgm(pair.right);
  // The unrelated stream first, a colour-less copy of the left image at another time.
  await add(other, BigInt(pair.left_stamp_ns) - 3000000n, image(l, BigInt(pair.left_stamp_ns) - 3000000n, "other"), imageWriter);
  // The right camera's message before the left's: arrival order is not pairing order.
  await add(right, pair.right_stamp_ns, image(r, pair.right_stamp_ns, "right"), imageWriter);
  await add(left, pair.left_stamp_ns, image(l, pair.left_stamp_ns, "left"), imageWriter);
  if (leftInfo !== null) await add(leftInfo, pair.left_stamp_ns, info(spec.left_info, pair.left_stamp_ns, "left"), infoWriter);
  if (rightInfo !== null) await add(rightInfo, pair.right_stamp_ns, info(spec.right_info, pair.right_stamp_ns, "right"), infoWriter);
  written++;
}
await writer.end();
await handle.close();
emit({ pairs: written });
