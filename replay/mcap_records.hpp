#pragma once
// MCAP records (https://mcap.dev/spec, format version 0): opcodes, the record structs this
// project writes and reads, and their little-endian serialization.
//
// Layout of a file as McapWriter writes it:
//
//   magic Header
//   Schema Channel ...                  (data section, written when they are added)
//   Chunk MessageIndex... Chunk ...     (every message inside a chunk)
//   DataEnd                             (CRC32 of every byte before it)
//   Schema... Channel... Statistics ChunkIndex...     (summary, grouped by opcode)
//   SummaryOffset...                    (one per group)
//   Footer magic                        (summary CRC32)
//
// All CRCs are CRC-32 (ISO-HDLC, the one of zlib and PNG), as the specification asks.
//
// No OpenCV and no threads here: pure byte handling, unit-tested on its own.

#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace stereod::mcap {

// The 8 bytes that open and close every MCAP file: 0x89 "MCAP" '0' "\r\n".
inline constexpr uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', 0x30, '\r', '\n'};
inline constexpr std::size_t kMagicSize = sizeof(kMagic);
// Every record: opcode (1 byte) and content length (uint64).
inline constexpr std::size_t kRecordPrefixSize = 9;
// Footer content: summary_start, summary_offset_start (uint64), summary_crc (uint32).
inline constexpr std::size_t kFooterContentSize = 20;
// Largest chunk a reader decompresses: two images of the largest frame a replay takes
// (8192x8192 RGBA, 256 MiB each) and their neighbours fit; a chunk's stated size is
// checked against it, and against what its zstd blocks can hold, before it is allocated.
inline constexpr uint64_t kMaxUncompressedChunk = uint64_t{1} << 30;

enum class Op : uint8_t {
    Header = 0x01,
    Footer = 0x02,
    Schema = 0x03,
    Channel = 0x04,
    Message = 0x05,
    Chunk = 0x06,
    MessageIndex = 0x07,
    ChunkIndex = 0x08,
    Attachment = 0x09,
    AttachmentIndex = 0x0A,
    Statistics = 0x0B,
    Metadata = 0x0C,
    MetadataIndex = 0x0D,
    SummaryOffset = 0x0E,
    DataEnd = 0x0F,
};

// A file that is not MCAP, a record that does not parse, or a write that failed. what()
// says which record or file; code() is the matching positive errno (EINVAL for malformed
// content, EIO/ENOSPC/... from the system).
class McapError : public std::runtime_error {
  public:
    explicit McapError(const std::string& message, int code = EINVAL)
        : std::runtime_error(message), code_(code)
    {
    }
    int code() const noexcept { return code_; }

  private:
    int code_;
};

struct Header {
    std::string profile; // "ros2" for ROS 2 bags
    std::string library; // the writer's name and version
};

struct Schema {
    uint16_t id = 0;      // never 0 in a valid file
    std::string name;     // e.g. "sensor_msgs/msg/Image"
    std::string encoding; // e.g. "ros2msg"
    std::string data;     // the definition text (bytes)
};

struct Channel {
    uint16_t id = 0;
    uint16_t schema_id = 0; // 0: no schema
    std::string topic;
    std::string message_encoding; // e.g. "cdr"
    std::map<std::string, std::string> metadata;
};

// A message whose data lives in a buffer owned by someone else (the chunk being read or
// the writer's caller).
struct MessageView {
    uint16_t channel_id = 0;
    uint32_t sequence = 0;
    uint64_t log_time_ns = 0;
    uint64_t publish_time_ns = 0;
    std::string_view data;
};

// A Chunk record, with `records` compressed (as stored); the buffer is someone else's.
struct ChunkView {
    uint64_t message_start_time = 0;
    uint64_t message_end_time = 0;
    uint64_t uncompressed_size = 0;
    uint32_t uncompressed_crc = 0; // 0: not available
    std::string compression;
    std::string_view records;
};

struct ChunkIndex {
    uint64_t message_start_time = 0;
    uint64_t message_end_time = 0;
    uint64_t chunk_start_offset = 0; // from the start of the file, to the opcode
    uint64_t chunk_length = 0;       // the whole record, prefix included
    std::map<uint16_t, uint64_t> message_index_offsets;
    uint64_t message_index_length = 0;
    std::string compression; // "" or "zstd"
    uint64_t compressed_size = 0;
    uint64_t uncompressed_size = 0;
};

struct Statistics {
    uint64_t message_count = 0;
    uint16_t schema_count = 0;
    uint32_t channel_count = 0;
    uint32_t attachment_count = 0;
    uint32_t metadata_count = 0;
    uint32_t chunk_count = 0;
    uint64_t message_start_time = 0;
    uint64_t message_end_time = 0;
    std::map<uint16_t, uint64_t> channel_message_counts;
};

struct Footer {
    uint64_t summary_start = 0;        // 0: no summary
    uint64_t summary_offset_start = 0; // 0: no summary offsets
    uint32_t summary_crc = 0;          // 0: not available
};

// CRC-32 (zlib's) of `size` bytes, continuing from `crc` (0 to start).
uint32_t crc32(uint32_t crc, const void* data, std::size_t size) noexcept;

// Appends little-endian fields and records to a byte buffer.
class ByteWriter {
  public:
    explicit ByteWriter(std::string& out) : out_(out) {}

    void u8(uint8_t v) { out_.push_back(static_cast<char>(v)); }
    void u16(uint16_t v) { le(v, 2); }
    void u32(uint32_t v) { le(v, 4); }
    void u64(uint64_t v) { le(v, 8); }
    void bytes(std::string_view v) { out_.append(v); }
    // uint32 length + bytes (String, and the Schema's data).
    void str(std::string_view v);
    void stringMap(const std::map<std::string, std::string>& map);
    void u16u64Map(const std::map<uint16_t, uint64_t>& map);

    // Starts a record: writes the opcode and a placeholder length; endRecord() fills it in.
    std::size_t beginRecord(Op op);
    void endRecord(std::size_t begin);

    std::string& buffer() noexcept { return out_; }

  private:
    void le(uint64_t v, int n)
    {
        for (int i = 0; i < n; ++i) {
            out_.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
        }
    }
    std::string& out_;
};

// Reads little-endian fields from a record's content; every read is bounds-checked and
// throws McapError naming `what` when the content is too short.
class ByteReader {
  public:
    ByteReader(std::string_view data, const char* what) : data_(data), what_(what) {}

    uint8_t u8();
    uint16_t u16();
    uint32_t u32();
    uint64_t u64();
    std::string_view bytes(std::size_t n);
    std::string str();
    std::map<std::string, std::string> stringMap();
    std::map<uint16_t, uint64_t> u16u64Map();
    std::string_view rest() { return bytes(remaining()); }

    std::size_t remaining() const noexcept { return data_.size() - pos_; }
    std::size_t position() const noexcept { return pos_; }

  private:
    void need(std::size_t n) const;
    uint64_t le(int n);
    std::string_view data_;
    std::size_t pos_ = 0;
    const char* what_;
};

// Record serializers: each appends one whole record (opcode, length, content). The
// serializers and the parsers below follow one field list per record (mcap_records.cpp).
void writeHeader(ByteWriter& w, const Header& h);
void writeSchema(ByteWriter& w, const Schema& s);
void writeChannel(ByteWriter& w, const Channel& c);
void writeMessage(ByteWriter& w, const MessageView& m);
void writeChunk(ByteWriter& w, const ChunkView& c);
void writeChunkIndex(ByteWriter& w, const ChunkIndex& c);
void writeStatistics(ByteWriter& w, const Statistics& s);
void writeFooter(ByteWriter& w, const Footer& f);

// Record parsers: each takes a record's content (after opcode and length). Unknown fields
// at the end (later versions of the format) are ignored, as the specification asks.
Header parseHeader(std::string_view content);
Schema parseSchema(std::string_view content);
Channel parseChannel(std::string_view content);
MessageView parseMessage(std::string_view content);
ChunkView parseChunk(std::string_view content);
ChunkIndex parseChunkIndex(std::string_view content);
Statistics parseStatistics(std::string_view content);
Footer parseFooter(std::string_view content);

// The records of a chunk, uncompressed (zstd or none) and CRC-checked when the chunk
// carries a CRC. Throws McapError for an unknown compression, a size or CRC mismatch, a
// size above kMaxUncompressedChunk or above what the zstd frame's blocks can hold (a
// frame header may state any size: memory follows what the blocks can really give).
// `out` is reused: its capacity stays from chunk to chunk.
void decompressChunk(const ChunkView& chunk, std::string& out);

// zstd compression of `in` into `out` (replaced) at `level`. Throws McapError.
void zstdCompress(std::string_view in, std::string& out, int level);

// Calls f(Op, content, offset_in_buffer) for every complete record of a record sequence
// (a chunk's records). Throws McapError when the sequence ends inside a record.
template <typename F> void forEachRecord(std::string_view records, F&& f)
{
    std::size_t pos = 0;
    while (pos < records.size()) {
        ByteReader r(records.substr(pos), "record in chunk");
        const auto op = static_cast<Op>(r.u8());
        const uint64_t length = r.u64();
        if (length > records.size() - pos - kRecordPrefixSize) {
            throw McapError("record in chunk at offset " + std::to_string(pos) +
                            " runs past the end of the chunk");
        }
        f(op, records.substr(pos + kRecordPrefixSize, length), pos);
        pos += kRecordPrefixSize + length;
    }
}

} // namespace stereod::mcap
