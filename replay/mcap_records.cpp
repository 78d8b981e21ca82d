#include "replay/mcap_records.hpp"

#include <concepts>
#include <limits>
#include <type_traits>

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

namespace {

// Each record's fields in file order, as the specification lists them: the one description
// that the serializer (FieldWriter, record const) and the parser (FieldReader, every read
// bounds-checked by ByteReader) both follow, so the two cannot drift apart. A field's C++
// type is its width on disk: FieldReader takes it by reference, so a mismatch does not compile.
template <typename T, typename Record>
concept RecordOf = std::same_as<std::remove_const_t<T>, Record>;

template <RecordOf<Header> R, typename V> void fields(R& h, V& v)
{
    v.str(h.profile);
    v.str(h.library);
}

template <RecordOf<Schema> R, typename V> void fields(R& s, V& v)
{
    v.u16(s.id);
    v.str(s.name);
    v.str(s.encoding);
    v.str(s.data);
}

template <RecordOf<Channel> R, typename V> void fields(R& c, V& v)
{
    v.u16(c.id);
    v.u16(c.schema_id);
    v.str(c.topic);
    v.str(c.message_encoding);
    v.stringMap(c.metadata);
}

template <RecordOf<MessageView> R, typename V> void fields(R& m, V& v)
{
    v.u16(m.channel_id);
    v.u32(m.sequence);
    v.u64(m.log_time_ns);
    v.u64(m.publish_time_ns);
    v.rest(m.data);
}

template <RecordOf<ChunkView> R, typename V> void fields(R& c, V& v)
{
    v.u64(c.message_start_time);
    v.u64(c.message_end_time);
    v.u64(c.uncompressed_size);
    v.u32(c.uncompressed_crc);
    v.str(c.compression);
    v.u64Bytes(c.records);
}

template <RecordOf<ChunkIndex> R, typename V> void fields(R& c, V& v)
{
    v.u64(c.message_start_time);
    v.u64(c.message_end_time);
    v.u64(c.chunk_start_offset);
    v.u64(c.chunk_length);
    v.u16u64Map(c.message_index_offsets);
    v.u64(c.message_index_length);
    v.str(c.compression);
    v.u64(c.compressed_size);
    v.u64(c.uncompressed_size);
}

template <RecordOf<Statistics> R, typename V> void fields(R& s, V& v)
{
    v.u64(s.message_count);
    v.u16(s.schema_count);
    v.u32(s.channel_count);
    v.u32(s.attachment_count);
    v.u32(s.metadata_count);
    v.u32(s.chunk_count);
    v.u64(s.message_start_time);
    v.u64(s.message_end_time);
    v.u16u64Map(s.channel_message_counts);
}

template <RecordOf<Footer> R, typename V> void fields(R& f, V& v)
{
    v.u64(f.summary_start);
    v.u64(f.summary_offset_start);
    v.u32(f.summary_crc);
}

struct FieldWriter {
    ByteWriter& w;
    void u16(uint16_t v) { w.u16(v); }
    void u32(uint32_t v) { w.u32(v); }
    void u64(uint64_t v) { w.u64(v); }
    void str(std::string_view v) { w.str(v); }
    void stringMap(const std::map<std::string, std::string>& v) { w.stringMap(v); }
    void u16u64Map(const std::map<uint16_t, uint64_t>& v) { w.u16u64Map(v); }
    // The record's last field, running to its end (a Message's data).
    void rest(std::string_view v) { w.bytes(v); }
    // uint64 length + bytes (a Chunk's records).
    void u64Bytes(std::string_view v)
    {
        w.u64(v.size());
        w.bytes(v);
    }
};

struct FieldReader {
    ByteReader& r;
    void u16(uint16_t& v) { v = r.u16(); }
    void u32(uint32_t& v) { v = r.u32(); }
    void u64(uint64_t& v) { v = r.u64(); }
    void str(std::string& v) { v = r.str(); }
    void stringMap(std::map<std::string, std::string>& v) { v = r.stringMap(); }
    void u16u64Map(std::map<uint16_t, uint64_t>& v) { v = r.u16u64Map(); }
    void rest(std::string_view& v) { v = r.rest(); }
    void u64Bytes(std::string_view& v)
    {
        const uint64_t size = r.u64();
        v = r.bytes(size);
    }
};

template <typename Record> void writeRecord(ByteWriter& w, Op op, const Record& record)
{
    const auto at = w.beginRecord(op);
    FieldWriter writer{w};
    fields(record, writer);
    w.endRecord(at);
}

// `name` is the record's in the parser's error messages.
template <typename Record> Record parseRecord(std::string_view content, const char* name)
{
    ByteReader r(content, name);
    FieldReader reader{r};
    Record record;
    fields(record, reader);
    return record;
}

} // namespace

void writeHeader(ByteWriter& w, const Header& h)
{
    writeRecord(w, Op::Header, h);
}
void writeSchema(ByteWriter& w, const Schema& s)
{
    writeRecord(w, Op::Schema, s);
}
void writeChannel(ByteWriter& w, const Channel& c)
{
    writeRecord(w, Op::Channel, c);
}
void writeMessage(ByteWriter& w, const MessageView& m)
{
    writeRecord(w, Op::Message, m);
}
void writeChunk(ByteWriter& w, const ChunkView& c)
{
    writeRecord(w, Op::Chunk, c);
}
void writeChunkIndex(ByteWriter& w, const ChunkIndex& c)
{
    writeRecord(w, Op::ChunkIndex, c);
}
void writeStatistics(ByteWriter& w, const Statistics& s)
{
    writeRecord(w, Op::Statistics, s);
}
void writeFooter(ByteWriter& w, const Footer& f)
{
    writeRecord(w, Op::Footer, f);
}

Header parseHeader(std::string_view content)
{
    return parseRecord<Header>(content, "Header");
}
Schema parseSchema(std::string_view content)
{
    return parseRecord<Schema>(content, "Schema");
}
Channel parseChannel(std::string_view content)
{
    return parseRecord<Channel>(content, "Channel");
}
MessageView parseMessage(std::string_view content)
{
    return parseRecord<MessageView>(content, "Message");
}
ChunkView parseChunk(std::string_view content)
{
    return parseRecord<ChunkView>(content, "Chunk");
}
ChunkIndex parseChunkIndex(std::string_view content)
{
    return parseRecord<ChunkIndex>(content, "ChunkIndex");
}
Statistics parseStatistics(std::string_view content)
{
    return parseRecord<Statistics>(content, "Statistics");
}
Footer parseFooter(std::string_view content)
{
    return parseRecord<Footer>(content, "Footer");
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
