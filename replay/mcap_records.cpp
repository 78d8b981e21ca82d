#include "replay/mcap_records.hpp"

#include <limits>

#include <zlib.h>
#include <zstd.h>

namespace stereod::mcap {

uint32_t crc32(uint32_t crc, const void* data, std::size_t size) noexcept
{
    // zlib takes uInt lengths: feed large buffers in pieces.
    const auto* p = static_cast<const Bytef*>(data);
    uLong value = crc;
    while (size > 0) {
        const auto n = static_cast<uInt>(std::min<std::size_t>(size, 1u << 30));
        value = ::crc32(value, p, n);
        p += n;
        size -= n;
    }
    return static_cast<uint32_t>(value);
}

void ByteWriter::str(std::string_view v)
{
    if (v.size() > std::numeric_limits<uint32_t>::max()) {
        throw McapError("string or bytes field longer than 4 GiB");
    }
    u32(static_cast<uint32_t>(v.size()));
    bytes(v);
}

void ByteWriter::stringMap(const std::map<std::string, std::string>& map)
{
    const std::size_t at = out_.size();
    u32(0);
    for (const auto& [key, value] : map) {
        str(key);
        str(value);
    }
    const auto length = static_cast<uint32_t>(out_.size() - at - 4);
    for (int i = 0; i < 4; ++i) {
        out_[at + i] = static_cast<char>((length >> (8 * i)) & 0xFF);
    }
}

void ByteWriter::u16u64Map(const std::map<uint16_t, uint64_t>& map)
{
    u32(static_cast<uint32_t>(map.size() * 10));
    for (const auto& [key, value] : map) {
        u16(key);
        u64(value);
    }
}

std::size_t ByteWriter::beginRecord(Op op)
{
    const std::size_t begin = out_.size();
    u8(static_cast<uint8_t>(op));
    u64(0);
    return begin;
}

void ByteWriter::endRecord(std::size_t begin)
{
    const uint64_t length = out_.size() - begin - kRecordPrefixSize;
    for (int i = 0; i < 8; ++i) {
        out_[begin + 1 + i] = static_cast<char>((length >> (8 * i)) & 0xFF);
    }
}

void ByteReader::need(std::size_t n) const
{
    if (n > remaining()) {
        throw McapError(std::string(what_) + ": content too short (field at byte " +
                        std::to_string(pos_) + " needs " + std::to_string(n) + " bytes, " +
                        std::to_string(remaining()) + " left)");
    }
}

uint64_t ByteReader::le(int n)
{
    need(static_cast<std::size_t>(n));
    uint64_t v = 0;
    for (int i = 0; i < n; ++i) {
        v |= static_cast<uint64_t>(static_cast<uint8_t>(data_[pos_ + i])) << (8 * i);
    }
    pos_ += static_cast<std::size_t>(n);
    return v;
}

uint8_t ByteReader::u8()
{
    return static_cast<uint8_t>(le(1));
}
uint16_t ByteReader::u16()
{
    return static_cast<uint16_t>(le(2));
}
uint32_t ByteReader::u32()
{
    return static_cast<uint32_t>(le(4));
}
uint64_t ByteReader::u64()
{
    return le(8);
}

std::string_view ByteReader::bytes(std::size_t n)
{
    need(n);
    const std::string_view v = data_.substr(pos_, n);
    pos_ += n;
    return v;
}

std::string ByteReader::str()
{
    const uint32_t n = u32();
    return std::string(bytes(n));
}

std::map<std::string, std::string> ByteReader::stringMap()
{
    const uint32_t length = u32();
    ByteReader inner(bytes(length), what_);
    std::map<std::string, std::string> map;
    while (inner.remaining() > 0) {
        std::string key = inner.str();
        map[std::move(key)] = inner.str();
    }
    return map;
}

std::map<uint16_t, uint64_t> ByteReader::u16u64Map()
{
    const uint32_t length = u32();
    ByteReader inner(bytes(length), what_);
    std::map<uint16_t, uint64_t> map;
    while (inner.remaining() > 0) {
        const uint16_t key = inner.u16();
        map[key] = inner.u64();
    }
    return map;
}

void writeHeader(ByteWriter& w, const Header& h)
{
    const auto at = w.beginRecord(Op::Header);
    w.str(h.profile);
    w.str(h.library);
    w.endRecord(at);
}

void writeSchema(ByteWriter& w, const Schema& s)
{
    const auto at = w.beginRecord(Op::Schema);
    w.u16(s.id);
    w.str(s.name);
    w.str(s.encoding);
    w.str(s.data);
    w.endRecord(at);
}

void writeChannel(ByteWriter& w, const Channel& c)
{
    const auto at = w.beginRecord(Op::Channel);
    w.u16(c.id);
    w.u16(c.schema_id);
    w.str(c.topic);
    w.str(c.message_encoding);
    w.stringMap(c.metadata);
    w.endRecord(at);
}

void writeMessage(ByteWriter& w, const MessageView& m)
{
    const auto at = w.beginRecord(Op::Message);
    w.u16(m.channel_id);
    w.u32(m.sequence);
    w.u64(m.log_time_ns);
    w.u64(m.publish_time_ns);
    w.bytes(m.data);
    w.endRecord(at);
}

void writeChunkIndex(ByteWriter& w, const ChunkIndex& c)
{
    const auto at = w.beginRecord(Op::ChunkIndex);
    w.u64(c.message_start_time);
    w.u64(c.message_end_time);
    w.u64(c.chunk_start_offset);
    w.u64(c.chunk_length);
    w.u16u64Map(c.message_index_offsets);
    w.u64(c.message_index_length);
    w.str(c.compression);
    w.u64(c.compressed_size);
    w.u64(c.uncompressed_size);
    w.endRecord(at);
}

void writeStatistics(ByteWriter& w, const Statistics& s)
{
    const auto at = w.beginRecord(Op::Statistics);
    w.u64(s.message_count);
    w.u16(s.schema_count);
    w.u32(s.channel_count);
    w.u32(s.attachment_count);
    w.u32(s.metadata_count);
    w.u32(s.chunk_count);
    w.u64(s.message_start_time);
    w.u64(s.message_end_time);
    w.u16u64Map(s.channel_message_counts);
    w.endRecord(at);
}

void writeFooter(ByteWriter& w, const Footer& f)
{
    const auto at = w.beginRecord(Op::Footer);
    w.u64(f.summary_start);
    w.u64(f.summary_offset_start);
    w.u32(f.summary_crc);
    w.endRecord(at);
}

Header parseHeader(std::string_view content)
{
    ByteReader r(content, "Header");
    Header h;
    h.profile = r.str();
    h.library = r.str();
    return h;
}

Schema parseSchema(std::string_view content)
{
    ByteReader r(content, "Schema");
    Schema s;
    s.id = r.u16();
    s.name = r.str();
    s.encoding = r.str();
    s.data = r.str();
    return s;
}

Channel parseChannel(std::string_view content)
{
    ByteReader r(content, "Channel");
    Channel c;
    c.id = r.u16();
    c.schema_id = r.u16();
    c.topic = r.str();
    c.message_encoding = r.str();
    c.metadata = r.stringMap();
    return c;
}

MessageView parseMessage(std::string_view content)
{
    ByteReader r(content, "Message");
    MessageView m;
    m.channel_id = r.u16();
    m.sequence = r.u32();
    m.log_time_ns = r.u64();
    m.publish_time_ns = r.u64();
    m.data = r.rest();
    return m;
}

ChunkIndex parseChunkIndex(std::string_view content)
{
    ByteReader r(content, "ChunkIndex");
    ChunkIndex c;
    c.message_start_time = r.u64();
    c.message_end_time = r.u64();
    c.chunk_start_offset = r.u64();
    c.chunk_length = r.u64();
    c.message_index_offsets = r.u16u64Map();
    c.message_index_length = r.u64();
    c.compression = r.str();
    c.compressed_size = r.u64();
    c.uncompressed_size = r.u64();
    return c;
}

Statistics parseStatistics(std::string_view content)
{
    ByteReader r(content, "Statistics");
    Statistics s;
    s.message_count = r.u64();
    s.schema_count = r.u16();
    s.channel_count = r.u32();
    s.attachment_count = r.u32();
    s.metadata_count = r.u32();
    s.chunk_count = r.u32();
    s.message_start_time = r.u64();
    s.message_end_time = r.u64();
    s.channel_message_counts = r.u16u64Map();
    return s;
}

Footer parseFooter(std::string_view content)
{
    ByteReader r(content, "Footer");
    Footer f;
    f.summary_start = r.u64();
    f.summary_offset_start = r.u64();
    f.summary_crc = r.u32();
    return f;
}

ChunkView parseChunk(std::string_view content)
{
    ByteReader r(content, "Chunk");
    ChunkView c;
    c.message_start_time = r.u64();
    c.message_end_time = r.u64();
    c.uncompressed_size = r.u64();
    c.uncompressed_crc = r.u32();
    c.compression = r.str();
    const uint64_t size = r.u64();
    c.records = r.bytes(size);
    return c;
}

namespace {

// The most bytes the zstd frames in `data` can give, read from their block headers
// (RFC 8878, 3.1): a raw or RLE block gives the size its header states, a compressed one
// at most 128 KiB (Block_Maximum_Size, which no block may exceed). No output is produced and
// nothing is allocated, so a frame header stating more than its blocks hold is caught before its
// size is trusted. Throws McapError when the frames do not follow each other as the format says.
uint64_t zstdOutputBound(std::string_view data)
{
    constexpr uint32_t kFrameMagic = 0xFD2FB528;
    constexpr uint32_t kSkippableMagicMask = 0xFFFFFFF0;
    constexpr uint32_t kSkippableMagic = 0x184D2A50;
    constexpr uint64_t kMaxBlockBytes = 128 * 1024;
    constexpr std::size_t kDictionaryIdBytes[] = {0, 1, 2, 4};
    constexpr std::size_t kContentSizeBytes[] = {0, 2, 4, 8};
    uint64_t bound = 0;
    std::size_t pos = 0;
    while (pos < data.size()) {
        ByteReader r(data.substr(pos), "zstd frame");
        const uint32_t magic = r.u32();
        if ((magic & kSkippableMagicMask) == kSkippableMagic) {
            r.bytes(r.u32());
            pos += r.position();
            continue;
        }
        if (magic != kFrameMagic) {
            throw McapError("zstd chunk: no zstd frame at byte " + std::to_string(pos) +
                            " of its records");
        }
        const uint8_t descriptor = r.u8();
        const bool single_segment = (descriptor & 0x20) != 0;
        const bool checksum = (descriptor & 0x04) != 0;
        if ((descriptor & 0x08) != 0) {
            throw McapError("zstd chunk: frame at byte " + std::to_string(pos) +
                            " sets the reserved bit of its header");
        }
        if (!single_segment) {
            r.u8(); // Window_Descriptor
        }
        r.bytes(kDictionaryIdBytes[descriptor & 0x03]);
        const unsigned content_size_flag = descriptor >> 6;
        r.bytes(content_size_flag == 0 && single_segment ? 1
                                                         : kContentSizeBytes[content_size_flag]);
        bool last = false;
        while (!last) {
            const uint32_t header = r.u8() | (uint32_t{r.u8()} << 8) | (uint32_t{r.u8()} << 16);
            last = (header & 1) != 0;
            const uint32_t size = header >> 3;
            if (size > kMaxBlockBytes) {
                throw McapError("zstd chunk: a block of " + std::to_string(size) +
                                " bytes in the frame at byte " + std::to_string(pos) +
                                ", more than zstd's 128 KiB");
            }
            switch ((header >> 1) & 3) {
            case 0: // raw: its bytes as they are
                bound += size;
                r.bytes(size);
                break;
            case 1: // RLE: one byte, repeated
                bound += size;
                r.u8();
                break;
            case 2: // compressed
                bound += kMaxBlockBytes;
                r.bytes(size);
                break;
            default:
                throw McapError("zstd chunk: a block of the reserved type in the frame at byte " +
                                std::to_string(pos));
            }
        }
        if (checksum) {
            r.u32();
        }
        pos += r.position();
    }
    return bound;
}

} // namespace

void decompressChunk(const ChunkView& chunk, std::string& out)
{
    if (chunk.compression.empty()) {
        if (chunk.records.size() != chunk.uncompressed_size) {
            throw McapError("uncompressed chunk: records field of " +
                            std::to_string(chunk.records.size()) + " bytes, header says " +
                            std::to_string(chunk.uncompressed_size));
        }
        out.assign(chunk.records);
    } else if (chunk.compression == "zstd") {
        // The size is the file's word, and so is the frame's: both are checked, against the
        // limit and against what the frame's blocks can hold, before anything is allocated.
        if (chunk.uncompressed_size > kMaxUncompressedChunk) {
            throw McapError("zstd chunk: " + std::to_string(chunk.uncompressed_size) +
                            " bytes uncompressed, more than a chunk may hold (" +
                            std::to_string(kMaxUncompressedChunk >> 20) + " MiB)");
        }
        const unsigned long long frame_size =
            ZSTD_getFrameContentSize(chunk.records.data(), chunk.records.size());
        if (frame_size == ZSTD_CONTENTSIZE_ERROR) {
            throw McapError("zstd chunk: not a zstd frame");
        }
        if (frame_size != ZSTD_CONTENTSIZE_UNKNOWN && frame_size != chunk.uncompressed_size) {
            throw McapError("zstd chunk: uncompressed size " +
                            std::to_string(chunk.uncompressed_size) +
                            " does not match its frame's " + std::to_string(frame_size));
        }
        const uint64_t bound = zstdOutputBound(chunk.records);
        if (chunk.uncompressed_size > bound) {
            throw McapError("zstd chunk: " + std::to_string(chunk.uncompressed_size) +
                            " bytes uncompressed declared, but its " +
                            std::to_string(chunk.records.size()) +
                            " bytes of blocks hold at most " + std::to_string(bound));
        }
        out.resize(chunk.uncompressed_size);
        const std::size_t n =
            ZSTD_decompress(out.data(), out.size(), chunk.records.data(), chunk.records.size());
        if (ZSTD_isError(n)) {
            throw McapError(std::string("zstd chunk: ") + ZSTD_getErrorName(n));
        }
        if (n != chunk.uncompressed_size) {
            throw McapError("zstd chunk: " + std::to_string(n) +
                            " bytes uncompressed, header says " +
                            std::to_string(chunk.uncompressed_size));
        }
    } else {
        throw McapError("chunk compressed with '" + chunk.compression +
                        "', which this reader does not support (only zstd and none)");
    }
    if (chunk.uncompressed_crc != 0 && crc32(0, out.data(), out.size()) != chunk.uncompressed_crc) {
        throw McapError("chunk CRC mismatch: the chunk is corrupt");
    }
}

void zstdCompress(std::string_view in, std::string& out, int level)
{
    out.resize(ZSTD_compressBound(in.size()));
    const std::size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), level);
    if (ZSTD_isError(n)) {
        throw McapError(std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
    }
    out.resize(n);
}

} // namespace stereod::mcap
