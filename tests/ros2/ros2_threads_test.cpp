// The ROS 2 node's threads under load, for ThreadSanitizer (label threaded): the image
// source's reading thread and sync thread against a writer, a consumer of the ring and a
// reader of status(); its camera_info taken while the calibration and status() are read;
// the publisher's thread against the thread that offers results and one that reads its
// counters and sets a late calibration's geometry. Everything in one process, on the
// loopback interface, in a DDS domain no other running test holds; the peers are Cyclone DDS
// entities on a participant of their own (sharing the process's domain with the code under test).
#include <atomic>
#include <chrono>
#include <cstring>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "base/clock.hpp"
#include "ros2/dds_participant.hpp"
#include "ros2/ros2_image_source.hpp"
#include "ros2/ros2_publisher.hpp"
#include "ros2_dds_types.h"
#include "tests/support/dds_domain.hpp"

namespace stereod::ros2 {
namespace {

using namespace std::chrono_literals;

DdsDiscovery testDomain(const test::DdsDomainLease& lease)
{
    DdsDiscovery discovery;
    discovery.domain_id = lease.id();
    discovery.localhost_only = true;
    return discovery;
}

// The publisher tests' settings, on the test's own domain, up to 1000 frames a second.
Ros2Settings publisherSettings(const std::string& ns, const test::DdsDomainLease& domain)
{
    Ros2Settings settings;
    settings.ns = ns;
    settings.discovery = testDomain(domain);
    settings.max_rate_hz = 1000;
    return settings;
}

// The publisher tests' rectified geometry: 64x48 pixels.
RectifiedGeometry smallGeometry()
{
    RectifiedGeometry geometry;
    geometry.image_size = ImageSize{64, 48};
    geometry.focal_px = 60;
    geometry.cx_px = 32;
    geometry.cy_px = 24;
    geometry.baseline_m = 0.1;
    return geometry;
}

// A 64x48 result of uniform images, depth 1 m, as the publisher tests offer it.
DepthResult smallResult()
{
    DepthResult result;
    result.left_rectified = cv::Mat(48, 64, CV_8UC1, cv::Scalar(100));
    result.disparity = cv::Mat(48, 64, CV_32FC1, cv::Scalar(6.0f));
    result.depth_m = cv::Mat(48, 64, CV_32FC1, cv::Scalar(1.0f));
    return result;
}

// The range the publisher tests' results were matched over.
DisparityRange smallRange()
{
    DisparityRange range;
    range.num_disparities = 16;
    range.closest_depth_m = 0.4;
    return range;
}

// A 64x48 mono8 image whose pixels all hold `value`, stamped `stamp_ns` (wall clock).
// Waits (up to 10 s) until each of the two writers has matched a reader: until then,
// written samples are lost.
void waitForReaders(const dds_entity_t (&writers)[2])
{
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    while ((DdsParticipant::matchedReaders(writers[0]) == 0 ||
            DdsParticipant::matchedReaders(writers[1]) == 0) &&
           std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(10ms);
}

sensor_msgs_msg_dds__Image_ monoImage(std::vector<uint8_t>& pixels, uint8_t value, int64_t stamp_ns,
                                      char* encoding, char* frame_id)
{
    pixels.assign(64 * 48, value);
    sensor_msgs_msg_dds__Image_ image{};
    image.header.stamp.sec = static_cast<int32_t>(stamp_ns / 1'000'000'000);
    image.header.stamp.nanosec = static_cast<uint32_t>(stamp_ns % 1'000'000'000);
    image.header.frame_id = frame_id;
    image.height = 48;
    image.width = 64;
    image.encoding = encoding;
    image.step = 64;
    image.data._buffer = pixels.data();
    image.data._length = image.data._maximum = static_cast<uint32_t>(pixels.size());
    return image;
}

TEST(Ros2Threads, SourceReadsPairsWhileStatusIsReadAndStopsUnderLoad)
{
    Ros2SourceOptions options;
    const test::DdsDomainLease domain;
    options.discovery = testDomain(domain);
    options.frame_size = cv::Size(64, 48);
    options.sync.max_skew_ns = 1'000'000;
    options.stall_timeout_ns = 1'000'000'000;
    Ros2ImageSource source(options);
    PairRing ring(4);
    ASSERT_EQ(source.start(ring), 0) << source.status().last_error;

    DdsParticipant peer(options.discovery);
    const dds_entity_t writers[2] = {
        peer.makeWriter("rt/stereo/left/image_raw", sensor_msgs_msg_dds__Image__desc,
                        QosProfile::SensorData),
        peer.makeWriter("rt/stereo/right/image_raw", sensor_msgs_msg_dds__Image__desc,
                        QosProfile::SensorData)};
    waitForReaders(writers);
    ASSERT_EQ(DdsParticipant::matchedReaders(writers[0]), 1u);

    std::atomic<bool> done{false};
    std::atomic<int> written{0};
    std::thread writer([&] {
        char encoding[] = "mono8";
        char frame_id[] = "cam";
        std::vector<uint8_t> pixels[2];
        for (int i = 0; !done.load(); ++i) {
            const int64_t stamp_ns = realtimeOffsetNs() + monotonicNowNs();
            // The pair's number in its pixels, left and right alike.
            for (int side = 0; side < 2; ++side) {
                const sensor_msgs_msg_dds__Image_ image = monoImage(
                    pixels[side], static_cast<uint8_t>(i % 251), stamp_ns, encoding, frame_id);
                dds_write(writers[side], &image);
            }
            written.fetch_add(1);
            std::this_thread::sleep_for(2ms);
        }
    });
    std::thread watcher([&] {
        while (!done.load()) {
            const SourceStatus status = source.status();
            EXPECT_EQ(status.cameras.size(), 2u);
            std::this_thread::sleep_for(1ms);
        }
    });

    int pairs = 0;
    int mismatched = 0;
    const auto until = std::chrono::steady_clock::now() + 2s;
    while (std::chrono::steady_clock::now() < until) {
        if (std::optional<StereoPair> pair = ring.tryPop()) {
            ++pairs;
            const uint8_t left = pair->left->image.at<uint8_t>(47, 63);
            const uint8_t right = pair->right->image.at<uint8_t>(0, 0);
            mismatched += (left != right || pair->left->stamp_ns != pair->right->stamp_ns) ? 1 : 0;
        } else {
            std::this_thread::sleep_for(1ms);
        }
    }
    // Stopped while the writer still writes and the watcher still reads.
    source.stop();
    done.store(true);
    writer.join();
    watcher.join();

    EXPECT_GT(pairs, 50) << written.load() << " pairs written";
    EXPECT_EQ(mismatched, 0);
    const SourceStatus status = source.status();
    EXPECT_EQ(status.state, SourceState::Stopped);
    EXPECT_GE(status.pairs, static_cast<uint64_t>(pairs));
    EXPECT_EQ(status.cameras[0].bad_frames, 0u);
    while (ring.tryPop()) {
    }
}

// The camera_info of a 64x48 rectified rig (focal 50 px, baseline 0.1 m; `focal_px` other
// than 50 makes another one), stamped with the wall clock.
sensor_msgs_msg_dds__CameraInfo_ cameraInfo(bool right, double focal_px, double* d, char* model,
                                            char* frame_id)
{
    sensor_msgs_msg_dds__CameraInfo_ info{};
    const int64_t stamp_ns = realtimeOffsetNs() + monotonicNowNs();
    info.header.stamp.sec = static_cast<int32_t>(stamp_ns / 1'000'000'000);
    info.header.stamp.nanosec = static_cast<uint32_t>(stamp_ns % 1'000'000'000);
    info.header.frame_id = frame_id;
    info.height = 48;
    info.width = 64;
    info.distortion_model = model;
    info.d._buffer = d;
    info.d._length = info.d._maximum = 5;
    const double k[9] = {focal_px, 0, 32, 0, focal_px, 24, 0, 0, 1};
    std::memcpy(info.k, k, sizeof k);
    const double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    std::memcpy(info.r, r, sizeof r);
    const double p[12] = {focal_px, 0, 32, right ? -focal_px * 0.1 : 0.0, 0, focal_px, 24, 0, 0,
                          0,        1, 0};
    std::memcpy(info.p, p, sizeof p);
    return info;
}

// camera_info taken on the reading thread while another thread asks for the calibration
// and the status: the first pair is the calibration, a changed one later only a warning.
TEST(Ros2Threads, SourceTakesCameraInfoWhileTheCalibrationAndStatusAreRead)
{
    Ros2SourceOptions options;
    const test::DdsDomainLease domain;
    options.discovery = testDomain(domain);
    options.frame_size = cv::Size(64, 48);
    options.left_info_topic = "/stereo/left/camera_info";
    options.right_info_topic = "/stereo/right/camera_info";
    Ros2ImageSource source(options);
    PairRing ring(4);
    ASSERT_EQ(source.start(ring), 0) << source.status().last_error;

    DdsParticipant peer(options.discovery);
    const dds_entity_t writers[2] = {
        peer.makeWriter("rt/stereo/left/camera_info", sensor_msgs_msg_dds__CameraInfo__desc,
                        QosProfile::Reliable),
        peer.makeWriter("rt/stereo/right/camera_info", sensor_msgs_msg_dds__CameraInfo__desc,
                        QosProfile::Reliable)};
    waitForReaders(writers);
    ASSERT_EQ(DdsParticipant::matchedReaders(writers[1]), 1u);

    std::atomic<bool> done{false};
    std::atomic<bool> taken{false};
    std::thread writer([&] {
        char model[] = "plumb_bob";
        char frame_id[] = "cam";
        double d[5] = {};
        for (int i = 0; !done.load(); ++i) {
            // Once taken, another focal length: ignored.
            const double focal_px = taken.load() ? 60.0 : 50.0;
            for (int side = 0; side < 2; ++side) {
                const sensor_msgs_msg_dds__CameraInfo_ info =
                    cameraInfo(side == 1, focal_px, d, model, frame_id);
                dds_write(writers[side], &info);
            }
            std::this_thread::sleep_for(2ms);
        }
    });
    std::thread watcher([&] {
        while (!done.load()) {
            EXPECT_EQ(source.status().cameras.size(), 2u);
            std::this_thread::sleep_for(1ms);
        }
    });
    std::optional<CameraInfoCalibration> calibration;
    const auto until = std::chrono::steady_clock::now() + 10s;
    while (!calibration && std::chrono::steady_clock::now() < until) {
        calibration = source.cameraInfoCalibration();
        std::this_thread::sleep_for(1ms);
    }
    taken.store(true);
    std::vector<std::string> warnings;
    const auto later = std::chrono::steady_clock::now() + 5s;
    while (warnings.size() < 2 && std::chrono::steady_clock::now() < later) {
        warnings = source.status().warnings;
        std::this_thread::sleep_for(5ms);
    }
    source.stop();
    done.store(true);
    writer.join();
    watcher.join();

    ASSERT_TRUE(calibration.has_value());
    EXPECT_EQ(calibration->origin, "/stereo/left/camera_info + /stereo/right/camera_info");
    EXPECT_EQ(calibration->calibration.rectified.focal_px, 50.0);
    EXPECT_NEAR(calibration->calibration.rectified.baseline_m, 0.1, 1e-12);
    EXPECT_EQ(source.cameraInfoCalibration()->calibration.rectified.focal_px, 50.0);
    ASSERT_EQ(warnings.size(), 2u);
    EXPECT_EQ(warnings[0], "/stereo/left/camera_info changed after the calibration was taken "
                           "from it: ignored (a restart takes the new one)");
}

TEST(Ros2Threads, PublisherPublishesWhileResultsAreOfferedAndCountersRead)
{
    const test::DdsDomainLease domain;
    const Ros2Settings settings = publisherSettings("/threads", domain);
    const RectifiedGeometry geometry = smallGeometry();
    Ros2Publisher publisher(settings, geometry, NearestSettings{}, CameraPose{});
    ASSERT_EQ(publisher.start(), "");

    // A reader of the depth and of the Range, so that those channels are matched and filled.
    DdsParticipant peer(settings.discovery);
    const dds_entity_t readers[2] = {
        peer.makeReader("rt/threads/depth", sensor_msgs_msg_dds__Image__desc,
                        QosProfile::SensorData),
        peer.makeReader("rt/threads/nearest", sensor_msgs_msg_dds__Range__desc,
                        QosProfile::Reliable)};
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    while (publisher.counters().readers < 2 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(10ms);
    ASSERT_GE(publisher.counters().readers, 2u);

    std::atomic<bool> done{false};
    std::thread offering([&] {
        DepthResult result = smallResult();
        while (!done.load()) {
            ++result.frame;
            publisher.offerFrame(result, realtimeOffsetNs() + monotonicNowNs(), true, smallRange(),
                                 CameraPose{}, "{\"valid\":false}");
            std::this_thread::sleep_for(1ms);
        }
    });
    std::thread counting([&] {
        // And a calibration that arrives late, as a ROS 2 driver's camera_info does: the
        // geometry set while the thread publishes with it.
        RectifiedGeometry later = geometry;
        while (!done.load()) {
            EXPECT_EQ(publisher.counters().write_errors, 0u);
            later.baseline_m = later.baseline_m == 0.1 ? 0.12 : 0.1;
            publisher.setGeometry(later);
            std::this_thread::sleep_for(1ms);
        }
    });

    uint64_t received[2] = {0, 0};
    const auto until = std::chrono::steady_clock::now() + 2s;
    while (std::chrono::steady_clock::now() < until) {
        for (int r = 0; r < 2; ++r) {
            std::array<ddsi_serdata*, 8> samples{};
            std::array<dds_sample_info_t, 8> infos{};
            const dds_return_t n =
                dds_takecdr(readers[r], samples.data(), 8, infos.data(), DDS_ANY_STATE);
            for (int i = 0; i < n; ++i) {
                received[r] += infos[static_cast<std::size_t>(i)].valid_data ? 1 : 0;
                ddsi_serdata_unref(samples[static_cast<std::size_t>(i)]);
            }
        }
        std::this_thread::sleep_for(1ms);
    }
    // Stopped while results are still offered and counters read.
    publisher.stop();
    done.store(true);
    offering.join();
    counting.join();

    const Ros2Counters counters = publisher.counters();
    EXPECT_GT(counters.frames, 50u);
    EXPECT_GT(received[0], 20u);
    EXPECT_GT(received[1], 20u);
    EXPECT_FALSE(counters.publishing);
}

// A reader of the points that matches while frames flow gets as its first cloud a whole
// frame's, in the left camera's colours: never the empty, colourless cloud of a frame
// whose points nobody read when it was offered (the match landing between the frame's
// offer and its publishing). Frames are offered back to back, so that one always waits.
TEST(Ros2Threads, APointsReaderMatchedMidStreamFirstGetsAWholeCloudInColour)
{
    const test::DdsDomainLease domain;
    const Ros2Settings settings = publisherSettings("/midstream", domain);
    Ros2Publisher publisher(settings, smallGeometry(), NearestSettings{}, CameraPose{});
    ASSERT_EQ(publisher.start(), "");

    constexpr uint32_t kPoints = 1000;
    std::atomic<bool> done{false};
    std::thread offering([&] {
        DepthResult result = smallResult();
        result.left_rectified_colour = cv::Mat(48, 64, CV_8UC3, cv::Scalar(30, 20, 10));
        result.cloud.assign(kPoints, CloudPoint{0.1f, 0.2f, 1.0f, 100.0f});
        result.cloud_colour.assign(kPoints, CloudColour{10, 20, 30});
        while (!done.load()) {
            ++result.frame;
            publisher.offerFrame(result, realtimeOffsetNs() + monotonicNowNs(), true, smallRange(),
                                 CameraPose{}, "{\"valid\":false}");
            std::this_thread::yield();
        }
    });

    DdsParticipant peer(settings.discovery);
    for (int attempt = 0; attempt < 5; ++attempt) {
        const dds_entity_t reader = peer.makeReader(
            "rt/midstream/points", sensor_msgs_msg_dds__PointCloud2__desc, QosProfile::SensorData);
        bool got = false;
        const auto deadline = std::chrono::steady_clock::now() + 10s;
        while (!got && std::chrono::steady_clock::now() < deadline) {
            void* sample = nullptr;
            dds_sample_info_t info{};
            const dds_return_t n = dds_take(reader, &sample, &info, 1, 1);
            if (n <= 0) {
                std::this_thread::sleep_for(1ms);
                continue;
            }
            if (info.valid_data) {
                const auto* cloud = static_cast<const sensor_msgs_msg_dds__PointCloud2_*>(sample);
                EXPECT_EQ(cloud->point_step, 20u) << "attempt " << attempt;
                EXPECT_EQ(cloud->fields._length, 5u) << "attempt " << attempt;
                EXPECT_EQ(cloud->width, kPoints / static_cast<uint32_t>(settings.points_step))
                    << "attempt " << attempt;
                got = true;
            }
            dds_return_loan(reader, &sample, n);
        }
        EXPECT_TRUE(got) << "attempt " << attempt << ": no cloud for 10 s";
        dds_delete(reader);
    }
    done.store(true);
    offering.join();
    publisher.stop();
}

} // namespace
} // namespace stereod::ros2
