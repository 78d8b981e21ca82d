// The camera frame sources against the fake V4L2 device (tests/fake_v4l2): two cameras
// paired by stereo sync, and one side-by-side camera. Real images (OpenCV's Aloe pair) in
// every pixel format; sync under jitter, skew and a clock offset; a camera unplugged and
// replugged, stalled, or delivering corrupt frames. The capture and sync threads run for
// real, so CI also runs these under ThreadSanitizer.

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <unistd.h>

#include "capture/frame_pool.hpp"
#include "capture/side_by_side_source.hpp"
#include "capture/stereo_camera_source.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/fake_cameras.hpp"

namespace stereod {
namespace {

namespace fs = std::filesystem;
using test::waitFor;

constexpr const char* kLeft = "/dev/video-fake-stereo-left";
constexpr const char* kRight = "/dev/video-fake-stereo-right";
constexpr const char* kSideBySide = "/dev/video-fake-sbs";
constexpr int kWidth = 320;
constexpr int kHeight = 240;
constexpr int64_t kMs = 1'000'000;

class CameraSourceTest : public ::testing::Test {
  protected:
    void SetUp() override
    {
        dir_ = fs::temp_directory_path() /
               ("stereod_sources_" + std::to_string(::getpid()) + "_" +
                ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::create_directories(dir_);
        const std::string samples = test::opencvSamplesDir();
        for (int side = 0; side < 2; ++side) {
            const cv::Mat image = cv::imread(samples + (side == 0 ? "/aloeL.jpg" : "/aloeR.jpg"),
                                             cv::IMREAD_GRAYSCALE);
            ASSERT_FALSE(image.empty()) << "OpenCV sample Aloe pair missing";
            cv::resize(image, scene_[side], cv::Size(kWidth, kHeight), 0, 0, cv::INTER_AREA);
            ASSERT_TRUE(cv::imwrite(imagePath(side), scene_[side]));
        }
        cv::Mat whole;
        cv::hconcat(scene_[0], scene_[1], whole);
        ASSERT_TRUE(cv::imwrite((dir_ / "sbs.png").string(), whole));
    }

    void TearDown() override
    {
        stereod_fake_v4l2_unload();
        fs::remove_all(dir_);
    }

    std::string imagePath(int side) const
    {
        return (dir_ / (side == 0 ? "left.png" : "right.png")).string();
    }

    // Two fake cameras at 30 fps offering GREY, YUYV and MJPG at 320x240, each serving
    // its Aloe image; `left_extra`/`right_extra` are more YAML keys of each device.
    void loadPair(const std::string& left_extra = "", const std::string& right_extra = "")
    {
        std::ofstream file(dir_ / "devices.yaml");
        file << "seed: 5\ndevices:\n";
        for (int side = 0; side < 2; ++side) {
            file << "  - path: " << (side == 0 ? kLeft : kRight) << "\n"
                 << "    images: " << imagePath(side) << "\n"
                 << "    fps: [30]\n"
                 << "    formats:\n"
                 << "      - { fourcc: GREY, sizes: [320x240] }\n"
                 << "      - { fourcc: YUYV, sizes: [320x240] }\n"
                 << "      - { fourcc: MJPG, sizes: [320x240] }\n"
                 << (side == 0 ? left_extra : right_extra);
        }
        file.close();
        ASSERT_EQ(stereod_fake_v4l2_load((dir_ / "devices.yaml").c_str()), 0)
            << stereod_fake_v4l2_last_error();
    }

    static StereoCameraOptions options(PixelFormatChoice format, double max_skew_ms = 5.0)
    {
        StereoCameraOptions o;
        for (CameraSettings* s : {&o.left, &o.right}) {
            s->format = format;
            s->width = kWidth;
            s->height = kHeight;
            s->fps = 30.0;
            s->reopen_min_ms = 20;
            s->reopen_max_ms = 100;
            // Generous, so that a loaded machine (sanitizer builds) never looks stalled;
            // the stall test sets its own.
            s->stall_timeout_ms = 3000;
        }
        o.left.device = kLeft;
        o.right.device = kRight;
        o.sync.max_skew_ns = static_cast<int64_t>(max_skew_ms * 1e6);
        o.left.buffer_count = o.right.buffer_count = cameraBufferCount(4, o.sync, o.inbox_capacity);
        return o;
    }

    // Pops `count` pairs (a guard of 5 s against hangs) and checks each side against its
    // image within `max_mean_error` grey levels.
    void expectPairs(PairRing& ring, int count, double max_mean_error, int64_t max_skew_ns)
    {
        for (int i = 0; i < count; ++i) {
            std::optional<StereoPair> pair = popPair(ring);
            ASSERT_TRUE(pair) << "no pair " << i;
            ASSERT_EQ(pair->left->image.size(), cv::Size(kWidth, kHeight));
            ASSERT_EQ(pair->right->image.size(), cv::Size(kWidth, kHeight));
            cv::Mat diff;
            cv::absdiff(pair->left->image, scene_[0], diff);
            EXPECT_LE(cv::mean(diff)[0], max_mean_error) << "left of pair " << i;
            cv::absdiff(pair->right->image, scene_[1], diff);
            EXPECT_LE(cv::mean(diff)[0], max_mean_error) << "right of pair " << i;
            EXPECT_LE(std::llabs(pair->skewNs()), max_skew_ns);
        }
    }

    static std::optional<StereoPair> popPair(PairRing& ring)
    {
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (std::chrono::steady_clock::now() < deadline) {
            if (std::optional<StereoPair> pair = ring.tryPop())
                return pair;
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
        return std::nullopt;
    }

    static void drain(PairRing& ring)
    {
        while (ring.tryPop()) {
        }
    }

    fs::path dir_;
    cv::Mat scene_[2];
};

TEST_F(CameraSourceTest, EachPixelFormatGivesPairsOfTheRightImages)
{
    // MJPEG at quality 90 stays within a few grey levels of the source on average.
    const struct {
        PixelFormatChoice format;
        double max_mean_error;
    } cases[] = {{PixelFormatChoice::Grey, 0.0},
                 {PixelFormatChoice::Yuyv, 0.0},
                 {PixelFormatChoice::Mjpeg, 3.0}};
    for (const auto& c : cases) {
        SCOPED_TRACE(toString(c.format));
        loadPair();
        PairRing ring(4);
        StereoCameraSource source(options(c.format));
        ASSERT_EQ(source.frameSize(), cv::Size(kWidth, kHeight));
        ASSERT_EQ(source.start(ring), 0) << source.status().last_error;
        expectPairs(ring, 5, c.max_mean_error, 5 * kMs);
        const SourceStatus status = source.status();
        EXPECT_EQ(status.kind, "v4l2");
        EXPECT_EQ(status.state, SourceState::Running) << status.last_error;
        ASSERT_EQ(status.cameras.size(), 2u);
        EXPECT_EQ(status.cameras[0].name, "left");
        EXPECT_EQ(status.cameras[1].name, "right");
        EXPECT_GE(status.pairs, 5u);
        EXPECT_FALSE(status.clock_offset_detected);
        EXPECT_TRUE(status.warnings.empty()) << status.warnings.front();
        const V4l2CameraStatus left = source.cameraStatus(StereoSide::Left);
        EXPECT_EQ(left.format.format_name, c.format == PixelFormatChoice::Grey   ? "GREY"
                                           : c.format == PixelFormatChoice::Yuyv ? "YUYV"
                                                                                 : "MJPG");
        source.stop();
        drain(ring);
        stereod_fake_v4l2_unload();
    }
}

TEST_F(CameraSourceTest, RefusedFormatNamesTheCameraAndWhatItOffers)
{
    loadPair("", "");
    StereoCameraOptions o = options(PixelFormatChoice::Grey);
    o.right.width = 1920;
    o.right.height = 1080;
    PairRing ring(4);
    StereoCameraSource source(o);
    EXPECT_LT(source.start(ring), 0);
    const SourceStatus status = source.status();
    EXPECT_NE(status.last_error.find("right camera " + std::string(kRight)), std::string::npos)
        << status.last_error;
    EXPECT_NE(status.last_error.find("320x240"), std::string::npos) << status.last_error;
    EXPECT_EQ(ring.pushed(), 0u);
}

// Jitter of 1 ms on both, the right camera 2 ms behind: every pair within max_skew and
// no offset reported (2 ms is below half of 5 ms).
TEST_F(CameraSourceTest, JitterAndSkewPairWithinMaxSkew)
{
    loadPair("    jitter_ms: 1\n", "    jitter_ms: 1\n    phase_ms: 2\n");
    PairRing ring(4);
    StereoCameraSource source(options(PixelFormatChoice::Grey));
    ASSERT_EQ(source.start(ring), 0) << source.status().last_error;
    int64_t signed_sum_ns = 0;
    constexpr int kPairs = 30;
    for (int i = 0; i < kPairs; ++i) {
        std::optional<StereoPair> pair = popPair(ring);
        ASSERT_TRUE(pair);
        EXPECT_LE(std::llabs(pair->skewNs()), 5 * kMs);
        signed_sum_ns += pair->skewNs();
    }
    EXPECT_NEAR(static_cast<double>(signed_sum_ns) / kPairs / 1e6, 2.0, 0.8);
    const SourceStatus status = source.status();
    EXPECT_LE(status.skew_max_ms, 5.0);
    EXPECT_GT(status.skew_mean_ms, 0.5);
    source.stop();
    drain(ring);
}

// The right camera's frames come 12 ms after the left's, with max_skew 5 ms: no pair at
// all, every frame counted as unpaired, and the offset reported with its estimate.
TEST_F(CameraSourceTest, OffsetBeyondMaxSkewIsReportedNotAbsorbed)
{
    loadPair("", "    phase_ms: 12\n");
    PairRing ring(4);
    StereoCameraSource source(options(PixelFormatChoice::Grey));
    ASSERT_EQ(source.start(ring), 0) << source.status().last_error;
    ASSERT_TRUE(
        waitFor([&] { return source.status().clock_offset_detected; }, std::chrono::seconds(10)))
        << "unpaired " << source.status().unpaired_dropped;
    const SourceStatus status = source.status();
    EXPECT_EQ(status.pairs, 0u);
    EXPECT_EQ(ring.pushed(), 0u);
    EXPECT_NEAR(status.clock_offset_ms, 12.0, 1.0);
    EXPECT_GT(status.cameras[0].unpaired, 0u);
    EXPECT_GT(status.cameras[1].unpaired, 0u);
    ASSERT_FALSE(status.warnings.empty());
    EXPECT_NE(status.warnings.back().find("apart"), std::string::npos) << status.warnings.back();
    source.stop();
}

TEST_F(CameraSourceTest, UnpluggedCameraFailsTheSourceAndPairsResumeAfterReplug)
{
    loadPair();
    PairRing ring(4);
    StereoCameraSource source(options(PixelFormatChoice::Yuyv));
    ASSERT_EQ(source.start(ring), 0) << source.status().last_error;
    expectPairs(ring, 3, 0.0, 5 * kMs);

    ASSERT_EQ(stereod_fake_v4l2_unplug(kRight), 0);
    ASSERT_TRUE(waitFor([&] { return source.status().state == SourceState::Failed; }))
        << toString(source.status().state);
    SourceStatus status = source.status();
    EXPECT_NE(status.last_error.find("right camera"), std::string::npos) << status.last_error;
    EXPECT_EQ(status.cameras[0].state, SourceState::Running);
    EXPECT_EQ(status.cameras[1].state, SourceState::Failed);
    // No pair while one camera is gone, and the left camera keeps streaming.
    drain(ring);
    const uint64_t pairs_while_down = source.status().pairs;
    const uint64_t left_frames = status.cameras[0].frames;
    ASSERT_TRUE(waitFor([&] { return source.status().cameras[0].frames > left_frames + 3; }));
    EXPECT_EQ(source.status().pairs, pairs_while_down);

    ASSERT_EQ(stereod_fake_v4l2_replug(kRight), 0);
    ASSERT_TRUE(waitFor([&] { return source.status().state == SourceState::Running; }))
        << source.status().last_error;
    drain(ring);
    // Pairs resume, made of fresh frames only.
    const int64_t back_ns = monotonicNowNs();
    std::optional<StereoPair> pair = popPair(ring);
    ASSERT_TRUE(pair) << source.status().last_error;
    EXPECT_GT(pair->left->stamp_ns, back_ns - 200 * kMs);
    EXPECT_LE(std::llabs(pair->skewNs()), 5 * kMs);
    EXPECT_GE(source.cameraStatus(StereoSide::Right).reopens, 1u);
    pair.reset();
    source.stop();
    drain(ring);
}

TEST_F(CameraSourceTest, StalledCameraStallsTheSourceUntilFramesReturn)
{
    loadPair();
    StereoCameraOptions o = options(PixelFormatChoice::Grey);
    o.left.stall_timeout_ms = 200;
    o.right.stall_timeout_ms = 200;
    PairRing ring(4);
    StereoCameraSource source(o);
    ASSERT_EQ(source.start(ring), 0) << source.status().last_error;
    expectPairs(ring, 2, 0.0, 5 * kMs);
    ASSERT_EQ(stereod_fake_v4l2_stall(kLeft, 1500), 0);
    ASSERT_TRUE(waitFor([&] {
        const SourceState state = source.status().state;
        return state == SourceState::Stalled || state == SourceState::Failed;
    })) << toString(source.status().state);
    EXPECT_NE(source.status().last_error.find("left camera"), std::string::npos)
        << source.status().last_error;
    ASSERT_TRUE(waitFor([&] { return source.status().state == SourceState::Running; },
                        std::chrono::seconds(10)))
        << source.status().last_error;
    drain(ring);
    expectPairs(ring, 2, 0.0, 5 * kMs);
    source.stop();
    drain(ring);
}

TEST_F(CameraSourceTest, CorruptFramesAreCountedAndNeverPaired)
{
    loadPair();
    PairRing ring(4);
    StereoCameraSource source(options(PixelFormatChoice::Mjpeg));
    ASSERT_EQ(source.start(ring), 0) << source.status().last_error;
    expectPairs(ring, 2, 3.0, 5 * kMs);
    ASSERT_EQ(stereod_fake_v4l2_corrupt(kLeft, 3, "truncated"), 0);
    ASSERT_TRUE(waitFor([&] { return source.status().cameras[0].bad_frames >= 3; }));
    // Every pair after the corruption still shows the real images.
    drain(ring);
    expectPairs(ring, 5, 3.0, 5 * kMs);
    const SourceStatus status = source.status();
    EXPECT_EQ(status.state, SourceState::Running);
    // The right frames of the corrupt instants found no partner.
    EXPECT_GE(status.cameras[1].unpaired, 3u);
    source.stop();
    drain(ring);
}

TEST_F(CameraSourceTest, SideBySideFramesSplitIntoTheTwoImagesWithoutCopy)
{
    std::ofstream file(dir_ / "devices.yaml");
    file << "devices:\n  - path: " << kSideBySide << "\n"
         << "    images: " << (dir_ / "sbs.png").string() << "\n"
         << "    fps: [30]\n"
         << "    formats:\n      - { fourcc: YUYV, sizes: [640x240] }\n";
    file.close();
    ASSERT_EQ(stereod_fake_v4l2_load((dir_ / "devices.yaml").c_str()), 0)
        << stereod_fake_v4l2_last_error();

    SideBySideOptions o;
    o.camera.device = kSideBySide;
    o.camera.format = PixelFormatChoice::Yuyv;
    o.camera.width = 2 * kWidth;
    o.camera.height = kHeight;
    o.camera.fps = 30.0;
    o.camera.buffer_count = 12;
    o.camera.keep_colour = true; // the left half's colour, not the right's
    PairRing ring(4);
    SideBySideSource source(o);
    EXPECT_EQ(source.frameSize(), cv::Size(kWidth, kHeight));
    ASSERT_EQ(source.start(ring), 0) << source.status().last_error;
    std::optional<StereoPair> previous;
    for (int i = 0; i < 4; ++i) {
        std::optional<StereoPair> pair = popPair(ring);
        ASSERT_TRUE(pair);
        cv::Mat diff;
        cv::absdiff(pair->left->image, scene_[0], diff);
        EXPECT_EQ(cv::countNonZero(diff), 0);
        cv::absdiff(pair->right->image, scene_[1], diff);
        EXPECT_EQ(cv::countNonZero(diff), 0);
        EXPECT_EQ(pair->skewNs(), 0);
        // Views into one buffer: the right half starts half a row after the left.
        EXPECT_EQ(pair->right->image.data, pair->left->image.data + kWidth);
        // The left half's colour is a view too, of the same picture (a grey scene: its
        // colour's grey is the luma within rounding); the right keeps none.
        ASSERT_EQ(pair->left->colour.type(), CV_8UC3);
        ASSERT_EQ(pair->left->colour.size(), pair->left->image.size());
        cv::Mat grey_of_colour;
        cv::cvtColor(pair->left->colour, grey_of_colour, cv::COLOR_BGR2GRAY);
        EXPECT_LE(cv::norm(grey_of_colour, pair->left->image, cv::NORM_INF), 1.0);
        EXPECT_TRUE(pair->right->colour.empty());
        if (previous) {
            EXPECT_GT(pair->index, previous->index);
        }
        previous = std::move(pair);
    }
    previous.reset();
    const SourceStatus status = source.status();
    EXPECT_EQ(status.kind, "side-by-side");
    EXPECT_EQ(status.state, SourceState::Running);
    EXPECT_GE(status.pairs, 4u);
    source.stop();
    drain(ring);
}

TEST(FrameSplitter, GivesTheWholeFrameBackWhenBothHalvesAreReleased)
{
    FramePool pool(2, cv::Size(8, 2));
    FrameSplitter splitter(1);
    FrameHandle whole = pool.acquire();
    ASSERT_TRUE(whole);
    whole->stamp_ns = 42;
    StereoPair pair;
    ASSERT_TRUE(splitter.split(std::move(whole), pair));
    EXPECT_EQ(pair.left->image.size(), cv::Size(4, 2));
    EXPECT_EQ(pair.right->stamp_ns, 42);
    // One slot: a second split is refused and its frame given back at once.
    StereoPair refused;
    EXPECT_FALSE(splitter.split(pool.acquire(), refused));
    EXPECT_EQ(pool.inUse(), 1u);
    pair.left.reset();
    EXPECT_EQ(pool.inUse(), 1u);
    pair.right.reset();
    EXPECT_EQ(pool.inUse(), 0u);
    EXPECT_EQ(splitter.inUse(), 0u);
}

TEST(FrameSplitter, SplitsTheColourAsTheGreyWhereItIsKept)
{
    FramePool pool(2, cv::Size(8, 2), CV_8UC1, true);
    for (const bool right_colour : {false, true}) {
        FrameSplitter splitter(1, right_colour);
        FrameHandle whole = pool.acquire();
        ASSERT_TRUE(whole);
        const uint8_t* colour = whole->colour.data;
        StereoPair pair;
        ASSERT_TRUE(splitter.split(std::move(whole), pair));
        EXPECT_EQ(pair.left->colour.size(), cv::Size(4, 2));
        EXPECT_EQ(pair.left->colour.data, colour);
        if (right_colour)
            EXPECT_EQ(pair.right->colour.data, colour + 4 * 3);
        else
            EXPECT_TRUE(pair.right->colour.empty());
        pair = StereoPair{};
        EXPECT_EQ(pool.inUse(), 0u);
    }
}

} // namespace
} // namespace stereod
