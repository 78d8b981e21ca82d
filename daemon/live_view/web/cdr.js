// ROS 2 CDR (little-endian XCDR1) readers for the messages the live view sends:
// sensor_msgs/msg/Image and sensor_msgs/msg/PointCloud2. Alignment counts from the end
// of the 4-byte encapsulation header.

class Reader {
  constructor(bytes) {
    this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    this.bytes = bytes;
    if (bytes.byteLength < 4 || bytes[0] !== 0 || bytes[1] !== 1) {
      throw new Error("not little-endian CDR");
    }
    this.pos = 4;
  }
  align(n) {
    const mis = (this.pos - 4) % n;
    if (mis) this.pos += n - mis;
  }
  u8() { return this.view.getUint8(this.pos++); }
  u32() { this.align(4); const v = this.view.getUint32(this.pos, true); this.pos += 4; return v; }
  i32() { this.align(4); const v = this.view.getInt32(this.pos, true); this.pos += 4; return v; }
  str() {
    const n = this.u32();
    const s = new TextDecoder().decode(this.bytes.subarray(this.pos, this.pos + Math.max(0, n - 1)));
    this.pos += n;
    return s;
  }
  octets() {
    const n = this.u32();
    const data = this.bytes.subarray(this.pos, this.pos + n);
    this.pos += n;
    return data;
  }
  header() {
    const sec = this.i32();
    const nanosec = this.u32();
    return { stampNs: BigInt(sec) * 1000000000n + BigInt(nanosec), frameId: this.str() };
  }
}

export function readImage(bytes) {
  const r = new Reader(bytes);
  const header = r.header();
  const height = r.u32();
  const width = r.u32();
  const encoding = r.str();
  r.u8(); // is_bigendian
  const step = r.u32();
  const data = r.octets();
  return { header, height, width, encoding, step, data };
}

export function readPointCloud2(bytes) {
  const r = new Reader(bytes);
  const header = r.header();
  const height = r.u32();
  const width = r.u32();
  const fields = [];
  const count = r.u32();
  for (let i = 0; i < count; ++i) {
    const name = r.str();
    const offset = r.u32();
    const datatype = r.u8();
    const n = r.u32();
    fields.push({ name, offset, datatype, count: n });
  }
  r.u8(); // is_bigendian
  const pointStep = r.u32();
  r.u32(); // row_step
  const data = r.octets();
  return { header, height, width, fields, pointStep, data };
}
