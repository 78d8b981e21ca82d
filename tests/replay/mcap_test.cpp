// MCAP writer and reader against each other, then against damage: a file cut at every
// kind of place (inside a chunk, between chunks, inside the summary), a flipped byte in a
// chunk. The independent check (@mcap/core reading our files, and writing files we read)
// is tests/mcap_interop.

#include <cstdint>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include "replay/mcap_reader.hpp"
#include "replay/mcap_writer.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod::mcap {
namespace {

struct Sent {
    uint16_t channel;
    uint64_t log_time;
    std::string data;
};

// A payload that compresses a little but not to nothing: message k on channel c.
std::string payload(int k, int c, std::size_t size)
{
    std::string s(size, '\0');
    uint32_t x = static_cast<uint32_t>(k * 7919 + c * 104729 + 1);
    for (std::size_t i = 0; i < size; ++i) {
        x = x * 1664525u + 1013904223u;
        s[i] = static_cast<char>((i % 4 == 0) ? (x >> 24) : (i / 64 + k));
    }
    return s;
}

// Writes `count` messages alternating over two channels (plus a third every 5th) with
// chunks of about `chunk_bytes`; returns what was sent.
std::vector<Sent> writeFile(const std::string& path, int count, WriterOptions options)
{
    Writer writer(path, options);
    const uint16_t image = writer.addSchema("sensor_msgs/msg/Image", "ros2msg", "uint32 height\n");
    const uint16_t info =
        writer.addSchema("sensor_msgs/msg/CameraInfo", "ros2msg", "uint32 height\n");
    const uint16_t left = writer.addChannel(image, "/left", "cdr", {{"offered_qos_profiles", ""}});
    const uint16_t right = writer.addChannel(image, "/right", "cdr");
    const uint16_t cam = writer.addChannel(info, "/info", "cdr");
    std::vector<Sent> sent;
    for (int k = 0; k < count; ++k) {
        const uint64_t t = 1'000'000'000ull + static_cast<uint64_t>(k) * 100'000'000ull;
        for (uint16_t c : {left, right}) {
            sent.push_back({c, t + c, payload(k, c, 3000)});
            writer.write(c, t + c, t + c, sent.back().data, static_cast<uint32_t>(k));
        }
        if (k % 5 == 0) {
            sent.push_back({cam, t, payload(k, cam, 100)});
            writer.write(cam, t, t, sent.back().data);
        }
    }
    writer.close();
    return sent;
}

std::vector<Sent> readAll(Reader& reader)
{
    std::vector<Sent> got;
    reader.forEachMessage([&](const MessageView& m, const MessageRef&) {
        got.push_back({m.channel_id, m.log_time_ns, std::string(m.data)});
    });
    return got;
}

std::string slurp(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

void spit(const std::string& path, std::string_view bytes)
{
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

WriterOptions smallChunks(WriterOptions::Compression compression)
{
    WriterOptions o;
    o.profile = "ros2";
    o.compression = compression;
    o.chunk_size_bytes = 20'000; // about 6 messages a chunk
    return o;
}

TEST(McapRecords, Crc32IsTheStandardOne)
{
    // The check value of CRC-32/ISO-HDLC.
    EXPECT_EQ(crc32(0, "123456789", 9), 0xCBF43926u);
}

TEST(McapRecords, RecordsRoundTrip)
{
    std::string buf;
    ByteWriter w(buf);
    Channel c{7, 3, "/stereo/left/image_raw", "cdr", {{"a", "1"}, {"b", "two"}}};
    writeChannel(w, c);
    ASSERT_EQ(static_cast<Op>(buf[0]), Op::Channel);
    const Channel back = parseChannel(std::string_view(buf).substr(kRecordPrefixSize));
    EXPECT_EQ(back.id, 7);
    EXPECT_EQ(back.schema_id, 3);
    EXPECT_EQ(back.topic, c.topic);
    EXPECT_EQ(back.metadata, c.metadata);
    // A cut record is refused with a reason, not read past its end.
    EXPECT_THROW(parseChannel(std::string_view(buf).substr(kRecordPrefixSize, 12)), McapError);
}

// Little-endian bytes of `v`, `n` wide: the expected layouts below are spelled out by hand
// from the specification's tables, not by the code under test.
std::string le(uint64_t v, int n)
{
    std::string s;
    for (int i = 0; i < n; ++i) {
        s.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
    }
    return s;
}

TEST(McapRecords, ChunkIsLaidOutAsTheSpecificationSays)
{
    std::string buf;
    ByteWriter w(buf);
    writeChunk(w, ChunkView{10, 20, 3, 0xAABBCCDDu, "zstd", "xyz"});
    const std::string content =
        le(10, 8) + le(20, 8) + le(3, 8) + le(0xAABBCCDD, 4) + le(4, 4) + "zstd" + le(3, 8) + "xyz";
    EXPECT_EQ(buf, std::string(1, '\x06') + le(content.size(), 8) + content);

    const ChunkView back = parseChunk(content);
    EXPECT_EQ(back.message_start_time, 10u);
    EXPECT_EQ(back.message_end_time, 20u);
    EXPECT_EQ(back.uncompressed_size, 3u);
    EXPECT_EQ(back.uncompressed_crc, 0xAABBCCDDu);
    EXPECT_EQ(back.compression, "zstd");
    EXPECT_EQ(back.records, "xyz");
    // Every cut, including one inside the records the length field promises, is refused.
    for (std::size_t n = 0; n < content.size(); ++n) {
        EXPECT_THROW(parseChunk(std::string_view(content).substr(0, n)), McapError) << n;
    }
}

TEST(McapRecords, SummaryRecordsRoundTripAndRefuseEveryCut)
{
    ChunkIndex index;
    index.message_start_time = 1;
    index.message_end_time = 2;
    index.chunk_start_offset = 3;
    index.chunk_length = 4;
    index.message_index_offsets = {{1, 5}, {2, 6}};
    index.message_index_length = 7;
    index.compression = "zstd";
    index.compressed_size = 8;
    index.uncompressed_size = 9;
    Statistics stats;
    stats.message_count = 11;
    stats.schema_count = 12;
    stats.channel_count = 13;
    stats.attachment_count = 14;
    stats.metadata_count = 15;
    stats.chunk_count = 16;
    stats.message_start_time = 17;
    stats.message_end_time = 18;
    stats.channel_message_counts = {{1, 19}};

    std::string buf;
    ByteWriter w(buf);
    writeChunkIndex(w, index);
    const std::size_t stats_at = buf.size();
    writeStatistics(w, stats);
    ASSERT_EQ(static_cast<Op>(buf[0]), Op::ChunkIndex);
    ASSERT_EQ(static_cast<Op>(buf[stats_at]), Op::Statistics);
    const std::string_view index_content =
        std::string_view(buf).substr(kRecordPrefixSize, stats_at - kRecordPrefixSize);
    const std::string_view stats_content =
        std::string_view(buf).substr(stats_at + kRecordPrefixSize);
    // 8 * 4 + (4 + 2 * 10) + 8 + (4 + 4) + 8 * 2, and 8 + 2 + 4 * 4 + 8 * 2 + (4 + 10).
    EXPECT_EQ(index_content.size(), 88u);
    EXPECT_EQ(stats_content.size(), 56u);

    const ChunkIndex index_back = parseChunkIndex(index_content);
    EXPECT_EQ(index_back.chunk_start_offset, 3u);
    EXPECT_EQ(index_back.message_index_offsets, index.message_index_offsets);
    EXPECT_EQ(index_back.message_index_length, 7u);
    EXPECT_EQ(index_back.compression, "zstd");
    EXPECT_EQ(index_back.uncompressed_size, 9u);
    const Statistics stats_back = parseStatistics(stats_content);
    EXPECT_EQ(stats_back.message_count, 11u);
    EXPECT_EQ(stats_back.schema_count, 12u);
    EXPECT_EQ(stats_back.chunk_count, 16u);
    EXPECT_EQ(stats_back.message_end_time, 18u);
    EXPECT_EQ(stats_back.channel_message_counts, stats.channel_message_counts);

    for (std::size_t n = 0; n < index_content.size(); ++n) {
        EXPECT_THROW(parseChunkIndex(index_content.substr(0, n)), McapError) << n;
    }
    for (std::size_t n = 0; n < stats_content.size(); ++n) {
        EXPECT_THROW(parseStatistics(stats_content.substr(0, n)), McapError) << n;
    }
}

TEST(McapFile, WrittenFileStartsAndEndsWithMagic)
{
    test::TempDir dir;
    writeFile(dir.file("a.mcap"), 3, smallChunks(WriterOptions::Compression::Zstd));
    const std::string bytes = slurp(dir.file("a.mcap"));
    ASSERT_GT(bytes.size(), 16u);
    const std::string magic(reinterpret_cast<const char*>(kMagic), kMagicSize);
    EXPECT_EQ(bytes.substr(0, 8), magic);
    EXPECT_EQ(bytes.substr(bytes.size() - 8), magic);
}

TEST(McapFile, RoundTripThroughTheSummary)
{
    for (auto compression : {WriterOptions::Compression::Zstd, WriterOptions::Compression::None}) {
        test::TempDir dir;
        const auto sent = writeFile(dir.file("a.mcap"), 40, smallChunks(compression));
        Reader reader(dir.file("a.mcap"));
        EXPECT_TRUE(reader.hasSummary());
        EXPECT_FALSE(reader.truncated());
        EXPECT_EQ(reader.header().profile, "ros2");
        ASSERT_EQ(reader.schemas().size(), 2u);
        EXPECT_EQ(reader.schemas().at(1).name, "sensor_msgs/msg/Image");
        ASSERT_EQ(reader.channels().size(), 3u);
        EXPECT_EQ(reader.channels().at(0).topic, "/left");
        EXPECT_EQ(reader.channels().at(0).metadata.count("offered_qos_profiles"), 1u);
        ASSERT_NE(reader.statistics(), nullptr);
        EXPECT_EQ(reader.statistics()->message_count, sent.size());
        EXPECT_EQ(reader.statistics()->channel_message_counts.at(2), 8u);
        EXPECT_GT(reader.chunks().size(), 5u) << "small chunks expected";
        EXPECT_EQ(reader.statistics()->chunk_count, reader.chunks().size());

        std::vector<MessageRef> refs;
        std::vector<Sent> got;
        reader.forEachMessage([&](const MessageView& m, const MessageRef& ref) {
            got.push_back({m.channel_id, m.log_time_ns, std::string(m.data)});
            refs.push_back(ref);
        });
        ASSERT_EQ(got.size(), sent.size());
        for (std::size_t i = 0; i < sent.size(); ++i) {
            EXPECT_EQ(got[i].channel, sent[i].channel) << i;
            EXPECT_EQ(got[i].log_time, sent[i].log_time) << i;
            EXPECT_TRUE(got[i].data == sent[i].data) << i;
        }
        // Random access by reference, backwards across chunks.
        for (std::size_t i = sent.size(); i-- > 0;) {
            const MessageView m = reader.message(refs[i]);
            EXPECT_EQ(m.log_time_ns, sent[i].log_time);
            EXPECT_TRUE(m.data == sent[i].data) << i;
        }
    }
}

TEST(McapFile, CompressionShrinksCompressibleData)
{
    test::TempDir dir;
    writeFile(dir.file("z.mcap"), 40, smallChunks(WriterOptions::Compression::Zstd));
    writeFile(dir.file("n.mcap"), 40, smallChunks(WriterOptions::Compression::None));
    EXPECT_LT(slurp(dir.file("z.mcap")).size(), slurp(dir.file("n.mcap")).size() * 8 / 10);
}

TEST(McapFile, RefusesToOverwriteAndNonMcap)
{
    test::TempDir dir;
    writeFile(dir.file("a.mcap"), 1, smallChunks(WriterOptions::Compression::Zstd));
    try {
        Writer again(dir.file("a.mcap"), WriterOptions{});
        FAIL() << "overwrote an existing file";
    } catch (const McapError& e) {
        EXPECT_EQ(e.code(), EEXIST);
    }
    spit(dir.file("text.mcap"), "this is not a bag at all, just some text");
    EXPECT_THROW(Reader(dir.file("text.mcap")), McapError);
    try {
        Reader missing(dir.file("missing.mcap"));
        FAIL();
    } catch (const McapError& e) {
        EXPECT_EQ(e.code(), ENOENT);
    }
}

// A recording killed mid-way is a prefix of the file. Cut the file at many places: every
// message of every chunk that ends before the cut is read, nothing after it.
TEST(McapFile, TruncatedFileKeepsEveryCompleteChunk)
{
    test::TempDir dir;
    const auto sent =
        writeFile(dir.file("full.mcap"), 40, smallChunks(WriterOptions::Compression::Zstd));
    const std::string bytes = slurp(dir.file("full.mcap"));
    std::vector<ChunkIndex> chunks;
    {
        Reader full(dir.file("full.mcap"));
        chunks = full.chunks();
    }
    ASSERT_GT(chunks.size(), 5u);

    // Messages that lie in chunks ending at or before `cut`.
    auto expected = [&](uint64_t cut) {
        std::size_t n = 0;
        Reader full(dir.file("full.mcap"));
        full.forEachMessage([&](const MessageView&, const MessageRef& ref) {
            const ChunkIndex& c = chunks[ref.chunk];
            if (c.chunk_start_offset + c.chunk_length <= cut) {
                ++n;
            }
        });
        return n;
    };

    std::vector<uint64_t> cuts;
    for (const auto& c : chunks) {
        cuts.push_back(c.chunk_start_offset);                      // just before a chunk
        cuts.push_back(c.chunk_start_offset + 5);                  // inside its prefix
        cuts.push_back(c.chunk_start_offset + c.chunk_length / 2); // in its middle
        cuts.push_back(c.chunk_start_offset + c.chunk_length);     // just after it
    }
    cuts.push_back(bytes.size() - 30); // inside the footer: summary lost, data intact
    for (const uint64_t cut : cuts) {
        SCOPED_TRACE("cut at byte " + std::to_string(cut));
        const std::string path = dir.file("cut.mcap");
        spit(path, std::string_view(bytes).substr(0, cut));
        Reader reader(path);
        EXPECT_FALSE(reader.hasSummary());
        const auto got = readAll(reader);
        const std::size_t want = expected(cut);
        ASSERT_EQ(got.size(), want);
        for (std::size_t i = 0; i < got.size(); ++i) {
            EXPECT_TRUE(got[i].data == sent[i].data) << i;
        }
        EXPECT_EQ(reader.channels().size(), 3u);
    }
}

TEST(McapFile, CorruptChunkEndsTheScanThere)
{
    test::TempDir dir;
    writeFile(dir.file("full.mcap"), 40, smallChunks(WriterOptions::Compression::None));
    std::string bytes = slurp(dir.file("full.mcap"));
    std::vector<ChunkIndex> chunks;
    {
        Reader full(dir.file("full.mcap"));
        chunks = full.chunks();
    }
    // No summary (cut before Data End), and a byte flipped in the third chunk's records.
    const std::size_t data_end = chunks.back().chunk_start_offset + chunks.back().chunk_length;
    bytes.resize(data_end);
    bytes[chunks[2].chunk_start_offset + chunks[2].chunk_length - 100] ^= 0x40;
    spit(dir.file("bad.mcap"), bytes);
    Reader reader(dir.file("bad.mcap"));
    EXPECT_TRUE(reader.truncated());
    EXPECT_NE(reader.problem().find("corrupt"), std::string::npos) << reader.problem();
    EXPECT_EQ(reader.chunks().size(), 2u);
}

// Bad input on purpose: every byte of a small file flipped in turn (and the file cut at
// every length). The reader either reads or throws McapError; it never crashes, reads out
// of bounds (the ASan build checks) or loops.
TEST(McapFile, DamagedFilesAreRefusedOrReadNeverCrash)
{
    test::TempDir dir;
    WriterOptions options = smallChunks(WriterOptions::Compression::Zstd);
    options.chunk_size_bytes = 2'000;
    {
        Writer writer(dir.file("small.mcap"), options);
        const uint16_t schema = writer.addSchema("s", "ros2msg", "uint8 x\n");
        const uint16_t channel = writer.addChannel(schema, "/t", "cdr", {{"k", "v"}});
        for (int k = 0; k < 6; ++k) {
            writer.write(channel, static_cast<uint64_t>(k), static_cast<uint64_t>(k),
                         payload(k, 0, 700));
        }
    }
    const std::string bytes = slurp(dir.file("small.mcap"));
    const std::string path = dir.file("bad.mcap");
    auto tryRead = [&](std::string_view content) {
        spit(path, content);
        try {
            Reader reader(path);
            std::size_t n = 0;
            reader.forEachMessage(
                [&](const MessageView& m, const MessageRef&) { n += m.data.size(); });
        } catch (const McapError&) {
        }
    };
    for (std::size_t i = 0; i < bytes.size(); ++i) {
        std::string damaged = bytes;
        damaged[i] = static_cast<char>(damaged[i] ^ 0xFF);
        tryRead(damaged);
    }
    for (std::size_t n = 0; n < bytes.size(); n += 7) {
        tryRead(std::string_view(bytes).substr(0, n));
    }
}

} // namespace
} // namespace stereod::mcap
