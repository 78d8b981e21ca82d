// Bags that lie, built by a test writer (tests/support/bags.hpp), against the parts that
// read them without a thread: an Image message's decoding (replay/image_message.hpp), a
// chunk's zstd frame (replay/mcap_records.hpp), the reader's way past a damaged chunk and
// the index's refusals, which must name what is wrong. The replay source on such bags is
// in replay_source_test.cpp, stereod on them in tests/daemon/stereod_cli_test.cpp.

#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "replay/image_message.hpp"
#include "replay/mcap_reader.hpp"
#include "replay/mcap_recording.hpp"
#include "ros2/messages.hpp"
#include "tests/support/bags.hpp"
#include "tests/support/recordings.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::ImageMessage;

std::string serialized(const ImageMessage& m)
{
    std::string out;
    ros2::serializeImage({ros2::Time::fromNs(m.stamp_ns), "camera"}, m.height, m.width, m.encoding,
                         m.step, m.data.data(), m.data.size(), out);
    return out;
}

ImageMessage lying(uint32_t width, uint32_t height, const char* encoding, uint32_t step,
                   std::size_t data_bytes)
{
    ImageMessage m;
    m.width = width;
    m.height = height;
    m.encoding = encoding;
    m.step = step;
    m.data.assign(data_bytes, '\x7f');
    return m;
}

void spit(const std::string& path, const std::string& bytes)
{
    std::ofstream(path, std::ios::binary) << bytes;
}

// The messages of issue 23 and their kin: every one refused with its reason, none handed
// to OpenCV (which faulted on the first two and threw on the third).
TEST(ImageMessage, SizesThatOverflowOrLieAreRefusedWithTheirReason)
{
    struct Case {
        ImageMessage message;
        const char* why; // a piece of the reason
    };
    const std::vector<Case> cases = {
        // width * 4 is 2^32: 0 in 32 bits, which step 0 "matched".
        {lying(1u << 30, 1, "rgba8", 0, 64), "more than a frame may have"},
        {lying(1u << 30, 1, "bgra8", 0, 64), "more than a frame may have"},
        // width * 3 is 2^32 + 2: 2 in 32 bits, which step 2 "matched".
        {lying(0x55555556u, 1, "rgb8", 2, 64), "more than a frame may have"},
        {lying(16, 4, "rgb8", 47, 47 * 4), "less than its row of 48 bytes"},
        {lying(16, 4, "mono8", 0, 64), "less than its row of 16 bytes"},
        {lying(0, 4, "mono8", 0, 64), "has no pixels"},
        {lying(16, 4, "mono16", 32, 128), "'mono16' is not replayed"},
        {lying(16, 4, "mono8", 16, 63), "fewer than step 16 x height 4"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.message.encoding + " " + std::to_string(c.message.width) + "x" +
                     std::to_string(c.message.height) + " step " + std::to_string(c.message.step));
        cv::Mat out;
        std::string reason;
        EXPECT_FALSE(decodeImageMessage(serialized(c.message), {}, out, reason));
        EXPECT_NE(reason.find(c.why), std::string::npos) << reason;
        EXPECT_TRUE(out.empty());
    }
    // Not a CDR message at all.
    cv::Mat out;
    std::string reason;
    EXPECT_FALSE(decodeImageMessage("\x00\x01", {}, out, reason));
    EXPECT_NE(reason.find("encapsulation"), std::string::npos) << reason;
}

TEST(ImageMessage, ColourIsConvertedAndTheExpectedSizeEnforced)
{
    // A 3x2 bgr8 image with padding at the end of each row (step 11 for 9 bytes).
    ImageMessage m = lying(3, 2, "bgr8", 11, 22);
    for (std::size_t i = 0; i < m.data.size(); ++i) // B, G, R of each pixel: 0, 30, 60
        m.data[i] = static_cast<char>(i % 11 < 9 ? 30 * (i % 11 % 3) : 255);
    cv::Mat out;
    std::string reason;
    ASSERT_TRUE(decodeImageMessage(serialized(m), {}, out, reason)) << reason;
    EXPECT_EQ(out.type(), CV_8UC1);
    EXPECT_EQ(out.size(), cv::Size(3, 2));
    // OpenCV's BGR weights: 0.114 B + 0.587 G + 0.299 R of (0, 30, 60).
    EXPECT_NEAR(out.at<uint8_t>(1, 2), 0.587 * 30 + 0.299 * 60, 1.0);

    // Of another size than the replay's: refused undecoded, both sizes named.
    EXPECT_FALSE(decodeImageMessage(serialized(m), cv::Size(96, 72), out, reason));
    EXPECT_NE(reason.find("is 3x2, 96x72 expected"), std::string::npos) << reason;

    // A truthful image one pixel past 8192x8192 (67 MB of data): refused by its size.
    ImageMessage large = lying(8193, 8192, "mono8", 8193, std::size_t{8193} * 8192);
    EXPECT_FALSE(decodeImageMessage(serialized(large), {}, out, reason));
    EXPECT_NE(reason.find("8193x8192 pixels, more than a frame may have"), std::string::npos)
        << reason;
}

// Issue 23: a chunk whose zstd frame header states N bytes, with one empty block. The
// reader allocated N (3 GiB: 3.2 GB resident for a 301-byte file; 1 TiB: std::bad_alloc
// out of the reader). It must refuse the chunk as corrupt, naming both sizes, without
// allocating what the header states.
TEST(McapZstd, AFrameHeaderStatingMoreThanItsBlocksHoldIsRefused)
{
    test::TempDir dir;
    const uint64_t tebibyte = uint64_t{1} << 40;
    const std::string path = dir.file("tib.mcap");
    spit(path, test::chunkBag(test::lyingZstdFrame(tebibyte), tebibyte));
    mcap::Reader reader(path); // threw std::bad_alloc
    EXPECT_TRUE(reader.truncated());
    EXPECT_NE(reader.problem().find("more than a chunk may hold"), std::string::npos)
        << reader.problem();

    // Within the chunk limit: refused for what its blocks hold.
    const uint64_t declared = uint64_t{768} << 20;
    spit(path, test::chunkBag(test::lyingZstdFrame(declared), declared));
    mcap::Reader within(path);
    EXPECT_TRUE(within.truncated());
    EXPECT_NE(within.problem().find("hold at most 0"), std::string::npos) << within.problem();

    // A frame that is not zstd at all, and one cut inside its block header.
    spit(path, test::chunkBag("not zstd at all", 100));
    EXPECT_NE(mcap::Reader(path).problem().find("not a zstd frame"), std::string::npos);
    const std::string frame = test::lyingZstdFrame(100);
    spit(path, test::chunkBag(frame.substr(0, frame.size() - 2), 100));
    EXPECT_NE(mcap::Reader(path).problem().find("corrupt"), std::string::npos);
}

// The same file opened in a child process, whose peak resident memory is its own: the
// refusal must come before the stated 768 MiB are allocated (it was 768 MiB plus the
// process before).
TEST(McapZstd, TheRefusalAllocatesNothingOfWhatTheHeaderStates)
{
    test::TempDir dir;
    const uint64_t declared = uint64_t{768} << 20;
    const std::string path = dir.file("lie.mcap");
    spit(path, test::chunkBag(test::lyingZstdFrame(declared), declared));
    int report[2];
    ASSERT_EQ(::pipe(report), 0);
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        ::close(report[0]);
        rusage before{};
        ::getrusage(RUSAGE_SELF, &before);
        long grown_kb = -1;
        try {
            mcap::Reader reader(path);
            rusage after{};
            ::getrusage(RUSAGE_SELF, &after);
            grown_kb = after.ru_maxrss - before.ru_maxrss;
        } catch (...) {
        }
        [[maybe_unused]] const ssize_t n = ::write(report[1], &grown_kb, sizeof grown_kb);
        ::_exit(0);
    }
    ::close(report[1]);
    long grown_kb = -2;
    ASSERT_EQ(::read(report[0], &grown_kb, sizeof grown_kb), static_cast<ssize_t>(sizeof grown_kb));
    ::close(report[0]);
    int status = 0;
    ::waitpid(child, &status, 0);
    ASSERT_GE(grown_kb, 0) << "the reader threw";
    EXPECT_LT(grown_kb, 32 * 1024) << "peak resident memory grew by " << grown_kb / 1024 << " MiB";
}

// Issue 23: one corrupt chunk rejected a whole bag that has a summary. Now its pairs are
// skipped, said once, and the other chunks' pairs are indexed.
TEST(McapBagIndex, ACorruptChunkCostsOnlyItsOwnPairs)
{
    test::TempDir dir;
    std::vector<test::TestPair> pairs = test::tsukubaPairs(12);
    std::vector<std::pair<ImageMessage, ImageMessage>> messages;
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        const auto t = static_cast<int64_t>(1'000'000'000 + 100'000'000 * k);
        messages.emplace_back(test::monoMessage(pairs[k].left, t),
                              test::monoMessage(pairs[k].right, t));
    }
    mcap::WriterOptions options;
    options.chunk_messages = 4; // two pairs a chunk
    const std::string path = dir.file("bag.mcap");
    test::writeStereoBag(path, messages, options);
    std::vector<mcap::ChunkIndex> chunks;
    {
        mcap::Reader reader(path);
        ASSERT_TRUE(reader.hasSummary());
        chunks = reader.chunks();
    }
    ASSERT_EQ(chunks.size(), 6u);
    std::string bytes;
    {
        std::ifstream in(path, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), {});
    }
    // A byte in the middle of the third chunk's compressed records.
    bytes[chunks[2].chunk_start_offset + chunks[2].chunk_length / 2] ^= 0x5A;
    spit(path, bytes);

    mcap::Reader reader(path);
    ASSERT_TRUE(reader.hasSummary()); // the summary's CRC does not cover the chunks
    const McapStereoIndex index = indexMcapStereo(reader, "", ""); // threw
    EXPECT_EQ(index.pairs.size(), 10u);
    ASSERT_EQ(index.problems.size(), 1u);
    EXPECT_NE(index.problems[0].find("chunk at byte " +
                                     std::to_string(chunks[2].chunk_start_offset) + " is corrupt"),
              std::string::npos)
        << index.problems[0];
}

std::string indexError(const std::string& path, const std::string& left = {},
                       const std::string& right = {})
{
    try {
        mcap::Reader reader(path);
        indexMcapStereo(reader, left, right);
    } catch (const mcap::McapError& e) {
        return e.what();
    }
    return "(indexed)";
}

// Issue 23: bags refused with a message that pointed elsewhere ("0 images ... have no
// stamps within 20000 us", "cannot tell left/right", the same topic twice as 10 and 0).
TEST(McapBagIndex, RefusalsSayWhatIsWrong)
{
    test::TempDir dir;
    const cv::Mat image(4, 6, CV_8UC1, cv::Scalar(9));
    std::vector<ImageMessage> good, broken;
    for (int k = 0; k < 3; ++k) {
        good.push_back(test::monoMessage(image, 1'000'000'000 + 100'000'000 * k));
        ImageMessage b = good.back();
        b.data.resize(10); // fewer bytes than step x height
        broken.push_back(b);
    }

    // Every left image malformed: the count of those and the first one's reason.
    const std::string malformed = dir.file("malformed.mcap");
    test::writeBag(malformed, {{"/stereo/left/image_raw", "sensor_msgs/msg/Image", "cdr", broken},
                               {"/stereo/right/image_raw", "sensor_msgs/msg/Image", "cdr", good}});
    std::string why = indexError(malformed);
    EXPECT_NE(why.find("0 images on /stereo/left/image_raw (and 3 that do not decode: "
                       "sensor_msgs/msg/Image: data holds 10 bytes, fewer than step 6 x height 4)"),
              std::string::npos)
        << why;
    EXPECT_EQ(why.find("have no stamps within"), std::string::npos) << why;

    // No Image topic in CDR: the bag's topics, with their encodings and schemas.
    const std::string foreign = dir.file("foreign.mcap");
    test::writeBag(foreign, {{"/cam/left", "sensor_msgs/msg/Image", "json", good},
                             {"/cam/right", "sensor_msgs/msg/Imu", "cdr", good}});
    why = indexError(foreign);
    EXPECT_NE(why.find("no topic carries sensor_msgs/msg/Image in CDR; its topics: /cam/left "
                       "(json, sensor_msgs/msg/Image), /cam/right (cdr, sensor_msgs/msg/Imu)"),
              std::string::npos)
        << why;
    // A topic named that is there but not an Image in CDR.
    const std::string mixed = dir.file("mixed.mcap");
    test::writeBag(mixed, {{"/a/image", "sensor_msgs/msg/Image", "cdr", good},
                           {"/b/image", "sensor_msgs/msg/Image", "cdr", good},
                           {"/imu", "sensor_msgs/msg/Imu", "cdr", good}});
    why = indexError(mixed, "/a/image", "/imu");
    EXPECT_NE(why.find("topic '/imu' is not sensor_msgs/msg/Image in CDR (it is cdr, "
                       "sensor_msgs/msg/Imu)"),
              std::string::npos)
        << why;

    // The same topic for both sides.
    why = indexError(mixed, "/a/image", "/a/image");
    EXPECT_NE(why.find("both set to the topic '/a/image'"), std::string::npos) << why;
}

// Colour images of a bag: their grey is what it always was, their colour the picture
// (rgb8, bgr8 exactly; YUV 4:2:2 through BT.601), and a 4:2:2 image of odd width or too
// short a step is refused before it is touched.
TEST(ImageMessage, ColourEncodingsGiveTheirGreyAndTheirColour)
{
    const cv::Mat bgr = [] {
        cv::Mat image(4, 6, CV_8UC3);
        cv::randu(image, 0, 255);
        return image;
    }();
    const auto message = [](const cv::Mat& pixels, const char* encoding) {
        ImageMessage m;
        m.width = static_cast<uint32_t>(pixels.cols);
        m.height = static_cast<uint32_t>(pixels.rows);
        m.encoding = encoding;
        m.step = static_cast<uint32_t>(pixels.cols * pixels.elemSize());
        m.data.assign(reinterpret_cast<const char*>(pixels.data),
                      pixels.total() * pixels.elemSize());
        return serialized(m);
    };
    cv::Mat rgb;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    cv::Mat grey_of_bgr;
    cv::cvtColor(bgr, grey_of_bgr, cv::COLOR_BGR2GRAY);
    for (const auto& [pixels, encoding] : {std::pair{bgr, "bgr8"}, std::pair{rgb, "rgb8"}}) {
        SCOPED_TRACE(encoding);
        cv::Mat grey, colour, grey_only;
        std::string why;
        ASSERT_TRUE(decodeImageMessage(message(pixels, encoding), {}, grey, colour, why)) << why;
        EXPECT_EQ(cv::norm(colour, bgr, cv::NORM_INF), 0.0);
        EXPECT_EQ(cv::norm(grey, grey_of_bgr, cv::NORM_INF), 0.0);
        ASSERT_TRUE(decodeImageMessage(message(pixels, encoding), {}, grey_only, why)) << why;
        EXPECT_EQ(cv::norm(grey_only, grey, cv::NORM_INF), 0.0);
    }

    // YUV 4:2:2, limited range: black (Y 16) and white (Y 235) pixel pairs, grey chroma.
    cv::Mat yuyv(2, 4, CV_8UC2);
    cv::Mat uyvy(2, 4, CV_8UC2);
    for (int x = 0; x < 4; ++x) {
        const uint8_t luma = x < 2 ? 16 : 235;
        yuyv.at<cv::Vec2b>(0, x) = yuyv.at<cv::Vec2b>(1, x) = cv::Vec2b(luma, 128);
        uyvy.at<cv::Vec2b>(0, x) = uyvy.at<cv::Vec2b>(1, x) = cv::Vec2b(128, luma);
    }
    for (const auto& [pixels, encoding] :
         {std::pair{yuyv, "yuv422_yuy2"}, std::pair{uyvy, "yuv422"}}) {
        SCOPED_TRACE(encoding);
        cv::Mat grey, colour;
        std::string why;
        ASSERT_TRUE(decodeImageMessage(message(pixels, encoding), {}, grey, colour, why)) << why;
        EXPECT_EQ(grey.at<uint8_t>(0, 0), 16) << "the grey is the luma plane";
        EXPECT_EQ(grey.at<uint8_t>(1, 3), 235);
        ASSERT_EQ(colour.type(), CV_8UC3);
        EXPECT_EQ(colour.at<cv::Vec3b>(0, 0), cv::Vec3b(0, 0, 0));
        EXPECT_GE(colour.at<cv::Vec3b>(1, 3)[1], 254);
    }

    // Mono: no colour, whatever the buffer held.
    cv::Mat grey, colour(2, 2, CV_8UC3);
    std::string why;
    ASSERT_TRUE(decodeImageMessage(message(grey_of_bgr, "mono8"), {}, grey, colour, why));
    EXPECT_TRUE(colour.empty());

    // 4:2:2 of odd width, or a step short of 2 bytes a pixel: refused, undecoded.
    EXPECT_FALSE(
        decodeImageMessage(serialized(lying(3, 2, "yuv422", 6, 12)), {}, grey, colour, why));
    EXPECT_NE(why.find("odd width"), std::string::npos) << why;
    EXPECT_TRUE(colour.empty());
    EXPECT_FALSE(
        decodeImageMessage(serialized(lying(4, 2, "yuv422_yuy2", 7, 64)), {}, grey, colour, why));
    EXPECT_NE(why.find("less than its row of 8 bytes"), std::string::npos) << why;
}

} // namespace
} // namespace stereod
