#include "tests/support/recordings.hpp"

#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <zlib.h>

#include "replay/recording.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod::test {

std::vector<TestPair> tsukubaPairs(int count, cv::Size size)
{
    const std::string dir = test::sharedDataDir() + "/middlebury/tsukuba/";
    const cv::Mat left = cv::imread(dir + "im3.png", cv::IMREAD_GRAYSCALE);
    const cv::Mat right = cv::imread(dir + "im4.png", cv::IMREAD_GRAYSCALE);
    EXPECT_FALSE(left.empty()) << dir << "im3.png missing";
    EXPECT_FALSE(right.empty()) << dir << "im4.png missing";
    EXPECT_LE(count, 16);
    std::vector<TestPair> pairs;
    if (left.empty() || right.empty())
        return pairs;
    for (int k = 0; k < count; ++k) {
        const cv::Rect roi(12 * k, 6 * k, size.width, size.height);
        TestPair pair;
        pair.left = left(roi).clone();
        pair.right = right(roi).clone();
        pairs.push_back(std::move(pair));
    }
    return pairs;
}

int64_t testSkewNs(int k)
{
    return (k % 2 == 0 ? 1 : -1) * int64_t{150'000} * (k % 3 + 1);
}

void stampPairs(std::vector<TestPair>& pairs, int64_t first_ns, int64_t spacing_ns)
{
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        pairs[k].left_stamp_ns = first_ns + static_cast<int64_t>(k) * spacing_ns;
        pairs[k].right_stamp_ns = pairs[k].left_stamp_ns + testSkewNs(static_cast<int>(k));
    }
}

void writeRecording(const std::string& dir, const std::vector<TestPair>& pairs,
                    const std::string& calibration_path)
{
    RecordingWriter writer(dir, calibration_path);
    for (const TestPair& pair : pairs)
        writer.write(pair.left, pair.right, pair.left_stamp_ns, pair.right_stamp_ns);
}

bool samePixels(const cv::Mat& a, const cv::Mat& b)
{
    return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

void writeGarbage(const std::string& path, std::size_t bytes)
{
    std::mt19937 rng(1234);
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    for (std::size_t i = 0; i < bytes; ++i)
        out.put(static_cast<char>(rng() & 0xFF));
}

namespace {

void appendBigEndian32(std::vector<uint8_t>& out, uint32_t value)
{
    for (int shift = 24; shift >= 0; shift -= 8)
        out.push_back(static_cast<uint8_t>(value >> shift));
}

// Appends one PNG chunk: length, type, data, CRC of type and data.
void appendChunk(std::vector<uint8_t>& out, const char* type, const std::vector<uint8_t>& data)
{
    appendBigEndian32(out, static_cast<uint32_t>(data.size()));
    const std::size_t type_at = out.size();
    out.insert(out.end(), type, type + 4);
    out.insert(out.end(), data.begin(), data.end());
    const uLong crc = crc32(0L, out.data() + type_at, static_cast<uInt>(4 + data.size()));
    appendBigEndian32(out, static_cast<uint32_t>(crc));
}

} // namespace

void writeDecompressionBomb(const std::string& path, cv::Size size)
{
    std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    std::vector<uint8_t> header;
    appendBigEndian32(header, static_cast<uint32_t>(size.width));
    appendBigEndian32(header, static_cast<uint32_t>(size.height));
    header.insert(header.end(), {8, 0, 0, 0, 0}); // 8-bit grey, deflate, no filter, no interlace
    appendChunk(png, "IHDR", header);

    // Each row: filter type 0, then `width` zero bytes; deflated as a stream.
    z_stream stream{};
    ASSERT_EQ(deflateInit(&stream, 9), Z_OK);
    const std::vector<uint8_t> row(static_cast<std::size_t>(size.width) + 1, 0);
    std::vector<uint8_t> compressed;
    std::vector<uint8_t> chunk(1 << 16);
    for (int y = 0; y <= size.height; ++y) {
        const bool last = y == size.height;
        stream.next_in = last ? nullptr : const_cast<Bytef*>(row.data());
        stream.avail_in = last ? 0 : static_cast<uInt>(row.size());
        do {
            stream.next_out = chunk.data();
            stream.avail_out = static_cast<uInt>(chunk.size());
            deflate(&stream, last ? Z_FINISH : Z_NO_FLUSH);
            compressed.insert(compressed.end(), chunk.data(),
                              chunk.data() + (chunk.size() - stream.avail_out));
        } while (stream.avail_out == 0);
    }
    deflateEnd(&stream);
    appendChunk(png, "IDAT", compressed);
    appendChunk(png, "IEND", {});
    writeBytes(path, png);
}

std::vector<uint8_t> encode(const cv::Mat& image, const std::string& extension)
{
    std::vector<uint8_t> bytes;
    EXPECT_TRUE(cv::imencode(extension, image, bytes));
    return bytes;
}

void writeBytes(const std::string& path, const std::vector<uint8_t>& bytes)
{
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
}

std::string base64(const cv::Mat& image)
{
    static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const cv::Mat m = image.isContinuous() ? image : image.clone();
    const auto* p = m.data;
    const std::size_t n = m.total();
    std::string out;
    for (std::size_t i = 0; i < n; i += 3) {
        const uint32_t v = (uint32_t{p[i]} << 16) | (i + 1 < n ? uint32_t{p[i + 1]} << 8 : 0) |
                           (i + 2 < n ? uint32_t{p[i + 2]} : 0);
        out += table[(v >> 18) & 63];
        out += table[(v >> 12) & 63];
        out += i + 1 < n ? table[(v >> 6) & 63] : '=';
        out += i + 2 < n ? table[v & 63] : '=';
    }
    return out;
}

} // namespace stereod::test

#if defined(__SANITIZE_THREAD__)
// OpenCV's image codecs register GDAL on first use, and GDAL takes two of its own mutexes
// in both orders while doing so, on one thread: ThreadSanitizer reports a potential
// deadlock inside libgdal that has nothing to do with the code under test.
extern "C" const char* __tsan_default_suppressions()
{
    return "deadlock:libgdal.so\n";
}
#endif
