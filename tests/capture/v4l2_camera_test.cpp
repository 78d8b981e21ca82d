// V4l2Camera end to end against the fake device: each pixel format's frames equal the
// source image, timestamps (monotonic or stamped at dequeue), sequence gaps, corrupt
// frames, unplug and replug, stalls, and kernel buffers going back to the driver when the
// last holder lets go. The capture thread runs for real, so CI also runs these under
// ThreadSanitizer.

#include <cerrno>
#include <cmath>
#include <deque>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "capture/v4l2_camera.hpp"
#include "tests/support/fake_cameras.hpp"

namespace stereod {
namespace {

using test::FakeCameraTest;
using test::kFakeLeft;
using test::nextFrame;
using test::waitFor;

const char* const kAllFormats = "      - { fourcc: GREY, sizes: [320x240] }\n"
                                "      - { fourcc: YUYV, sizes: [320x240] }\n"
                                "      - { fourcc: MJPG, sizes: [320x240] }\n";

class V4l2CameraTest : public FakeCameraTest {
  protected:
    // Takes `count` frames, checks each against the scene within `max_mean_error` grey
    // levels, and checks stamps and sequence numbers.
    void expectFrames(V4l2Camera& camera, int count, double max_mean_error)
    {
        int64_t previous_stamp = 0;
        uint64_t previous_sequence = 0;
        for (int i = 0; i < count; ++i) {
            const int64_t before_ns = monotonicNowNs();
            std::optional<CapturedFrame> captured = nextFrame(ring_);
            ASSERT_TRUE(captured) << "no frame; " << camera.status().camera.last_error;
            const Frame& frame = *captured->frame;
            EXPECT_EQ(captured->camera_index, 7u);
            ASSERT_EQ(frame.image.type(), CV_8UC1);
            ASSERT_EQ(frame.image.size(), scene_.size());
            cv::Mat diff;
            cv::absdiff(frame.image, scene_, diff);
            EXPECT_LE(cv::mean(diff)[0], max_mean_error) << "frame " << i;
            // Capture happened before we got it, and not long before we asked (the ring
            // holds a few frames at most).
            EXPECT_LE(frame.stamp_ns, monotonicNowNs());
            EXPECT_GT(frame.stamp_ns, before_ns - 1'000'000'000);
            if (i > 0) {
                EXPECT_GT(frame.stamp_ns, previous_stamp);
                EXPECT_GT(frame.sequence, previous_sequence);
            }
            previous_stamp = frame.stamp_ns;
            previous_sequence = frame.sequence;
        }
    }

    // Starts a camera on ring_; TearDown stops it and releases every frame first.
    V4l2Camera& start(const CameraSettings& s, int expected_rc = 0)
    {
        stopCamera();
        camera_ = std::make_unique<V4l2Camera>(s, 7, "left");
        start_rc_ = camera_->start(ring_);
        EXPECT_EQ(start_rc_, expected_rc) << camera_->status().camera.last_error;
        return *camera_;
    }

    void stopCamera()
    {
        if (camera_)
            camera_->stop();
        while (ring_.tryPop()) {
        }
        camera_.reset();
    }

    void TearDown() override
    {
        stopCamera();
        FakeCameraTest::TearDown();
    }

    // Declared before the ring: frames still queued go back before the camera goes.
    std::unique_ptr<V4l2Camera> camera_;
    int start_rc_ = 0;
    // Smaller than the buffer count: GREY frames in the ring hold kernel buffers.
    CapturedRing ring_{2};
};

TEST_F(V4l2CameraTest, EachFormatDeliversTheSourceImage)
{
    struct Case {
        PixelFormatChoice format;
        const char* name;
        double max_mean_error; // grey levels
    };
    // GREY (the kernel buffer itself) and YUYV's luma are exact; JPEG at quality 90
    // loses about 3 grey levels on average on this textured scene.
    for (const Case& c :
         {Case{PixelFormatChoice::Grey, "GREY", 0.0}, Case{PixelFormatChoice::Yuyv, "YUYV", 0.0},
          Case{PixelFormatChoice::Mjpeg, "MJPG", 4.0}}) {
        SCOPED_TRACE(c.name);
        stopCamera();
        loadFake(kAllFormats);
        V4l2Camera& camera = start(settings(c.format));
        ASSERT_EQ(start_rc_, 0);
        expectFrames(camera, 10, c.max_mean_error);
        const V4l2CameraStatus status = camera.status();
        EXPECT_EQ(status.camera.state, SourceState::Running);
        EXPECT_EQ(status.format.format_name, c.name);
        EXPECT_TRUE(status.kernel_monotonic_stamps);
        EXPECT_EQ(status.camera.bad_frames, 0u);
        EXPECT_GE(status.camera.frames, 10u);
    }
}

TEST_F(V4l2CameraTest, ColourFormatsKeepTheCamerasColourWhenAsked)
{
    // The Aloe cut in colour: each format carries it as a camera would.
    const cv::Mat aloe = cv::imread(test::opencvSamplesDir() + "/aloeL.jpg", cv::IMREAD_COLOR);
    ASSERT_FALSE(aloe.empty());
    cv::Mat colour;
    cv::resize(aloe, colour, scene_.size(), 0, 0, cv::INTER_AREA);
    ASSERT_TRUE(cv::imwrite((dir_ / "scene.png").string(), colour));
    cv::Mat luma;
    cv::cvtColor(colour, luma, cv::COLOR_BGR2GRAY);

    struct Case {
        PixelFormatChoice format;
        const char* fourcc;
        double grey_error;   // mean grey levels
        double colour_error; // mean levels per channel
    };
    // YUYV's luma and packed RGB/BGR are exact, YUYV's colour shares its chroma between
    // pixel pairs; JPEG at quality 90 loses a few levels (4.8 per channel here).
    for (const Case& c : {Case{PixelFormatChoice::Yuyv, "YUYV", 0.0, 2.5},
                          Case{PixelFormatChoice::Mjpeg, "MJPG", 4.0, 6.0},
                          Case{PixelFormatChoice::Rgb24, "RGB3", 0.0, 0.0},
                          Case{PixelFormatChoice::Bgr24, "BGR3", 0.0, 0.0}}) {
        for (const bool keep : {true, false}) {
            SCOPED_TRACE(std::string(c.fourcc) + (keep ? " with colour" : " grey only"));
            stopCamera();
            loadFake(std::string("      - { fourcc: ") + c.fourcc + ", sizes: [320x240] }\n");
            CameraSettings s = settings(c.format);
            s.keep_colour = keep;
            V4l2Camera& camera = start(s);
            ASSERT_EQ(start_rc_, 0);
            for (int i = 0; i < 3; ++i) {
                std::optional<CapturedFrame> captured = nextFrame(ring_);
                ASSERT_TRUE(captured) << camera.status().camera.last_error;
                const Frame& frame = *captured->frame;
                cv::Mat diff;
                cv::absdiff(frame.image, luma, diff);
                EXPECT_LE(cv::mean(diff)[0], c.grey_error);
                if (!keep) {
                    EXPECT_TRUE(frame.colour.empty());
                    continue;
                }
                ASSERT_EQ(frame.colour.type(), CV_8UC3);
                ASSERT_EQ(frame.colour.size(), colour.size());
                cv::absdiff(frame.colour, colour, diff);
                const cv::Scalar mean = cv::mean(diff);
                EXPECT_LE((mean[0] + mean[1] + mean[2]) / 3.0, c.colour_error);
            }
            EXPECT_EQ(camera.status().format.colour, keep);
            EXPECT_EQ(camera.status().format.format_name, c.fourcc);
        }
    }
}

TEST_F(V4l2CameraTest, GreyCamerasHaveNoColourToKeep)
{
    loadFake(kAllFormats);
    CameraSettings s = settings(PixelFormatChoice::Grey);
    s.keep_colour = true;
    V4l2Camera& camera = start(s);
    ASSERT_EQ(start_rc_, 0);
    std::optional<CapturedFrame> captured = nextFrame(ring_);
    ASSERT_TRUE(captured);
    EXPECT_TRUE(captured->frame->colour.empty());
    EXPECT_FALSE(camera.status().format.colour);
}

TEST_F(V4l2CameraTest, StartRefusesWhatTheDeviceCannotDeliver)
{
    loadFake("      - { fourcc: YUYV, sizes: [640x480] }\n");
    V4l2Camera camera(settings(PixelFormatChoice::Auto), 0, "left");
    EXPECT_EQ(camera.start(ring_), -EINVAL);
    const V4l2CameraStatus status = camera.status();
    EXPECT_EQ(status.camera.state, SourceState::Failed);
    EXPECT_NE(status.camera.last_error.find("it offers: YUYV 640x480"), std::string::npos)
        << status.camera.last_error;

    CameraSettings absent = settings(PixelFormatChoice::Auto);
    absent.device = "/dev/video-fake-nothing";
    V4l2Camera missing(absent, 0, "right");
    EXPECT_EQ(missing.start(ring_), -ENOENT);
    EXPECT_NE(missing.status().camera.last_error.find("/dev/video-fake-nothing"),
              std::string::npos);
}

TEST_F(V4l2CameraTest, UnknownTimestampsAreStampedAtDequeue)
{
    // The fake then reports CLOCK_REALTIME stamps: trusting them would put frames decades
    // away from the monotonic clock.
    loadFake(kAllFormats, "    timestamps: unknown\n");
    V4l2Camera& camera = start(settings(PixelFormatChoice::Grey));
    ASSERT_EQ(start_rc_, 0);
    expectFrames(camera, 5, 0.0);
    EXPECT_FALSE(camera.status().kernel_monotonic_stamps);
}

TEST_F(V4l2CameraTest, SequenceGapsAreCountedAsDropped)
{
    loadFake(kAllFormats, "    drop_every: 4\n");
    V4l2Camera& camera = start(settings(PixelFormatChoice::Yuyv));
    ASSERT_EQ(start_rc_, 0);
    uint64_t first = 0;
    uint64_t last = 0;
    constexpr int kFrames = 24;
    for (int i = 0; i < kFrames; ++i) {
        std::optional<CapturedFrame> captured = nextFrame(ring_);
        ASSERT_TRUE(captured);
        (i == 0 ? first : last) = captured->frame->sequence;
    }
    camera.stop();
    const V4l2CameraStatus status = camera.status();
    // Every fourth frame is lost: at least (span / 4) gaps, and all frames the sequence
    // skipped were counted (frames we did not take stayed in the ring or were dropped
    // by it, which the camera does not count).
    const uint64_t span = last - first + 1;
    EXPECT_GE(status.sequence_gaps, span / 4 - 1);
    EXPECT_EQ(status.camera.dropped, status.sequence_gaps);
    EXPECT_GE(status.camera.frames, static_cast<uint64_t>(kFrames));
    while (ring_.tryPop()) {
    }
}

TEST_F(V4l2CameraTest, CorruptFramesAreCountedAndSkipped)
{
    struct Case {
        PixelFormatChoice format;
        const char* kind;
    };
    for (const Case& c :
         {Case{PixelFormatChoice::Mjpeg, "truncated"}, Case{PixelFormatChoice::Yuyv, "bytesused"},
          Case{PixelFormatChoice::Grey, "bytesused"}, Case{PixelFormatChoice::Grey, "error"}}) {
        SCOPED_TRACE(std::string(toString(c.format)) + " " + c.kind);
        stopCamera();
        loadFake(kAllFormats);
        V4l2Camera& camera = start(settings(c.format));
        ASSERT_EQ(start_rc_, 0);
        ASSERT_TRUE(nextFrame(ring_));
        ASSERT_EQ(stereod_fake_v4l2_corrupt(kFakeLeft, 3, c.kind), 0)
            << stereod_fake_v4l2_last_error();
        ASSERT_TRUE(waitFor([&] { return camera.status().camera.bad_frames >= 3; }));
        // Good frames follow, and every delivered frame is whole.
        for (int i = 0; i < 5; ++i) {
            std::optional<CapturedFrame> captured = nextFrame(ring_);
            ASSERT_TRUE(captured);
            cv::Mat diff;
            cv::absdiff(captured->frame->image, scene_, diff);
            EXPECT_LE(cv::mean(diff)[0], 4.0);
        }
        const V4l2CameraStatus status = camera.status();
        EXPECT_EQ(status.camera.bad_frames, 3u);
        EXPECT_EQ(status.camera.state, SourceState::Running);
        EXPECT_FALSE(status.camera.last_bad_frame.empty());
    }
}

TEST_F(V4l2CameraTest, UnplugFailsWithTheReasonAndReplugResumes)
{
    loadFake(kAllFormats);
    CameraSettings s = settings(PixelFormatChoice::Grey);
    s.reopen_min_ms = 20;
    s.reopen_max_ms = 80;
    V4l2Camera& camera = start(s);
    ASSERT_EQ(start_rc_, 0);
    ASSERT_TRUE(nextFrame(ring_));

    ASSERT_EQ(stereod_fake_v4l2_unplug(kFakeLeft), 0);
    ASSERT_TRUE(waitFor([&] { return camera.status().camera.state == SourceState::Failed; }));
    // The reason is the unplug's (ENODEV), or, once the first reopen (20 ms later) has
    // tried while the status was being read on a loaded machine, that the node is gone.
    const V4l2CameraStatus failed = camera.status();
    const std::string& reason = failed.camera.last_error;
    EXPECT_TRUE(reason.find(std::strerror(ENODEV)) != std::string::npos ||
                reason.find(std::strerror(ENOENT)) != std::string::npos)
        << reason;
    EXPECT_NE(reason.find(kFakeLeft), std::string::npos);

    // A frame dequeued before the unplug stays readable while held.
    while (ring_.tryPop()) {
    }
    ASSERT_EQ(stereod_fake_v4l2_replug(kFakeLeft), 0);
    ASSERT_TRUE(waitFor([&] { return camera.status().camera.state == SourceState::Running; }))
        << camera.status().camera.last_error;
    std::optional<CapturedFrame> captured = nextFrame(ring_);
    ASSERT_TRUE(captured);
    EXPECT_EQ(cv::norm(captured->frame->image, scene_, cv::NORM_INF), 0.0);
    const V4l2CameraStatus resumed = camera.status();
    EXPECT_EQ(resumed.reopens, 1u);
    EXPECT_TRUE(resumed.camera.last_error.empty()) << resumed.camera.last_error;
    captured.reset();
}

TEST_F(V4l2CameraTest, StallIsReportedAndClearsWhenFramesReturn)
{
    loadFake(kAllFormats);
    CameraSettings s = settings(PixelFormatChoice::Yuyv);
    s.stall_timeout_ms = 100;
    V4l2Camera& camera = start(s);
    ASSERT_EQ(start_rc_, 0);
    ASSERT_TRUE(nextFrame(ring_));
    ASSERT_EQ(stereod_fake_v4l2_stall(kFakeLeft, 500), 0);
    ASSERT_TRUE(waitFor([&] { return camera.status().camera.state == SourceState::Stalled; }));
    EXPECT_NE(camera.status().camera.last_error.find("no frame for"), std::string::npos)
        << camera.status().camera.last_error;
    ASSERT_TRUE(waitFor([&] { return camera.status().camera.state == SourceState::Running; }));
    EXPECT_EQ(camera.status().reopens, 0u); // shorter than the reopen threshold (1 s)
}

TEST_F(V4l2CameraTest, HeldBuffersGoBackWhenTheLastHolderLetsGo)
{
    loadFake(kAllFormats);
    CameraSettings s = settings(PixelFormatChoice::Grey);
    s.buffer_count = 4;
    V4l2Camera& camera = start(s);
    ASSERT_EQ(start_rc_, 0);

    // Holding all but one buffer: the camera keeps delivering through the last one.
    std::deque<CapturedFrame> held;
    while (held.size() < 3) {
        std::optional<CapturedFrame> captured = nextFrame(ring_);
        ASSERT_TRUE(captured);
        held.push_back(std::move(*captured));
    }
    for (int i = 0; i < 5; ++i) {
        std::optional<CapturedFrame> captured = nextFrame(ring_);
        ASSERT_TRUE(captured) << "the camera stopped with one buffer free";
        EXPECT_EQ(cv::norm(captured->frame->image, scene_, cv::NORM_INF), 0.0);
    }

    // Holding all four: pool exhaustion is reported, not a hang.
    std::optional<CapturedFrame> fourth = nextFrame(ring_);
    ASSERT_TRUE(fourth);
    held.push_back(std::move(*fourth));
    ASSERT_TRUE(waitFor([&] { return camera.status().camera.state == SourceState::Stalled; }));
    V4l2CameraStatus status = camera.status();
    EXPECT_GE(status.pool_exhausted, 1u);
    EXPECT_NE(status.camera.last_error.find("pool exhausted"), std::string::npos)
        << status.camera.last_error;
    // Frames held are still the images they were.
    for (const CapturedFrame& frame : held)
        EXPECT_EQ(cv::norm(frame.frame->image, scene_, cv::NORM_INF), 0.0);

    // Releasing them (here, on this thread) gives the buffers back; capture resumes.
    held.clear();
    ASSERT_TRUE(waitFor([&] { return camera.status().camera.state == SourceState::Running; }));
    ASSERT_TRUE(nextFrame(ring_));
}

TEST_F(V4l2CameraTest, FramesReleasedOnAnotherThreadAreRequeued)
{
    loadFake(kAllFormats);
    CameraSettings s = settings(PixelFormatChoice::Grey);
    s.buffer_count = 3;
    V4l2Camera& camera = start(s);
    ASSERT_EQ(start_rc_, 0);
    // Far more frames than buffers, each released on a different thread than the one
    // that captured it and the one that took it.
    for (int i = 0; i < 30; ++i) {
        std::optional<CapturedFrame> captured = nextFrame(ring_);
        ASSERT_TRUE(captured);
        std::thread([frame = std::move(*captured)]() mutable { frame.frame.reset(); }).join();
    }
    EXPECT_EQ(camera.status().camera.state, SourceState::Running);
}

} // namespace
} // namespace stereod
