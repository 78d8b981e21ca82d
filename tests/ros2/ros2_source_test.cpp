// source.type ros2, fed by a ROS 2 camera driver nobody here wrote: a publisher built from
// eProsima Fast DDS (tests/ros2/fastdds_image_publisher.cpp) sends the Tsukuba pair on the
// two image topics over the loopback interface, in a DDS domain no other running test holds, and
// `stereod` reads its pairs from them. The distance is held to the same pair replayed from
// files; stamps too far apart, a malformed image and a publisher that goes away and comes
// back are each seen in what the service says. Without a calibration file the calibration
// comes from the driver's camera_info topics: the same distance as with the file, and a
// camera_info that cannot be used is refused by topic and field.
#include <algorithm>
#include <chrono>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ctl/client.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/calibration_formats.hpp"
#include "tests/daemon/live_view_service.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/dds_domain.hpp"
#include "tests/support/process.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;
using Json = nlohmann::ordered_json;
using test::ChildProcess;

class Ros2Source : public test::LiveViewE2e {
  protected:
    void SetUp() override
    {
        LiveViewE2e::SetUp();
        ::setenv("ROS_DOMAIN_ID", domain_.text().c_str(), 1);
    }

    void TearDown() override
    {
        publisher_.reset();
        ros2_service_.reset();
        ::unsetenv("ROS_DOMAIN_ID");
    }

    // The distance of the Tsukuba pair replayed from files by the same service and
    // calibration: what the ROS 2 source must give too.
    double replayedDistance()
    {
        startService("off");
        const Json reading = waitForReading(valid, 30s);
        service_.reset();
        EXPECT_TRUE(valid(reading)) << reading.dump();
        return valid(reading) ? reading["distance_m"].get<double>() : 0.0;
    }

    // stereod reading the two image topics of the Tsukuba pair's size.
    // `with_calibration_file`: --calib the Tsukuba pair's calibration; without it, the
    // calibration comes from the camera_info topics.
    void startRos2Service(const std::string& extra_source_yaml = {},
                          const std::string& extra_yaml = {}, bool with_calibration_file = true)
    {
        const std::string config = dir_.file("ros2-source.yaml");
        std::ofstream(config) << "source:\n  type: ros2\n  ros2:\n    width: 384\n"
                              << "    height: 288\n  stall_timeout_ms: 1000\n"
                              << extra_source_yaml << extra_yaml;
        std::vector<std::string> argv = {
            test::stereodPath(), "--config", config, "--socket", socket_, "--live-view", "off"};
        if (with_calibration_file) {
            argv.push_back("--calib");
            argv.push_back(calibration_);
        }
        ros2_service_ = std::make_unique<ChildProcess>(argv, dir_.file("stereod-ros2.log"));
        const auto deadline = std::chrono::steady_clock::now() + 30s;
        while (std::chrono::steady_clock::now() < deadline) {
            try {
                ProtocolClient client(socket_, 2000ms);
                client.request({{"cmd", "status"}});
                return;
            } catch (const std::exception&) {
            }
            std::this_thread::sleep_for(100ms);
        }
        FAIL() << "stereod did not answer within 30 s";
    }

    void publish(double seconds, const std::vector<std::string>& options = {})
    {
        std::vector<std::string> argv = {STEREOD_FASTDDS_IMAGE_PUBLISHER, domain_.text(),
                                         std::to_string(seconds), test::tsukubaDir() + "/im3.png",
                                         test::tsukubaDir() + "/im4.png"};
        argv.insert(argv.end(), options.begin(), options.end());
        publisher_ = std::make_unique<ChildProcess>(argv, dir_.file("publisher.log"));
    }

    Json distance()
    {
        ProtocolClient client(socket_, 10000ms);
        return client.request({{"cmd", "distance"}})["reading"];
    }

    // Polls the service's reading until `wanted` holds of it, or `limit` passes; the last
    // reading either way.
    // The left topic's status once two of its images were refused (or after 30 s).
    Json leftOnceBadTwice()
    {
        Json left;
        const auto deadline = std::chrono::steady_clock::now() + 30s;
        while (std::chrono::steady_clock::now() < deadline) {
            left = status()["source"]["cameras"][0];
            if (left["bad_frames"].get<int>() >= 2)
                break;
            std::this_thread::sleep_for(200ms);
        }
        return left;
    }

    template <typename Predicate> Json waitForReading(Predicate wanted, std::chrono::seconds limit)
    {
        Json reading;
        const auto deadline = std::chrono::steady_clock::now() + limit;
        while (std::chrono::steady_clock::now() < deadline) {
            try {
                reading = distance();
                if (wanted(reading))
                    return reading;
            } catch (const std::exception&) {
            }
            std::this_thread::sleep_for(100ms);
        }
        return reading;
    }

    static bool valid(const Json& reading) { return reading.value("valid", false); }

    // The Tsukuba calibration as a ROS camera_info pair of files, as `stereoctl export-ros`
    // writes them (and a driver's camera_info_manager loads them).
    std::pair<std::string, std::string> exportCameraInfo()
    {
        const std::string left = dir_.file("left.yaml");
        const std::string right = dir_.file("right.yaml");
        exportRosCameraInfo(loadCalibration(calibration_), left, right);
        return {left, right};
    }

    // The service's source warnings once one contains `text` (or after `limit`).
    Json waitForWarning(const std::string& text, std::chrono::seconds limit)
    {
        Json warnings;
        const auto deadline = std::chrono::steady_clock::now() + limit;
        while (std::chrono::steady_clock::now() < deadline) {
            warnings = status()["source"]["warnings"];
            for (const Json& warning : warnings)
                if (warning.get<std::string>().find(text) != std::string::npos)
                    return warnings;
            std::this_thread::sleep_for(200ms);
        }
        return warnings;
    }

    test::DdsDomainLease domain_;
    std::unique_ptr<ChildProcess> ros2_service_;
    std::unique_ptr<ChildProcess> publisher_;
};

std::string reasonCode(const Json& reading)
{
    return reading.contains("reason") && reading["reason"].is_object()
               ? reading["reason"].value("code", std::string())
               : std::string();
}

TEST_F(Ros2Source, DistanceEqualsTheSamePairReplayedFromFiles)
{
    const double replayed = replayedDistance();
    ASSERT_GT(replayed, 0.0);
    // Publishing as a ROS 2 node too: the source and the node share the process's domain.
    startRos2Service({}, "ros2:\n  enabled: true\n");
    ASSERT_FALSE(HasFailure());
    publish(60);
    const Json reading = waitForReading(valid, 30s);
    ASSERT_TRUE(valid(reading)) << reading.dump();
    // The same grey pixels (mono8 from the files as the replay reads them), the same
    // matcher: the same distance.
    EXPECT_DOUBLE_EQ(reading["distance_m"].get<double>(), replayed);

    const Json st = status();
    EXPECT_EQ(st["ros2"]["publishing"], true) << st["ros2"].dump();
    const Json source = st["source"];
    SCOPED_TRACE(source.dump());
    EXPECT_EQ(source["kind"], "ros2");
    EXPECT_EQ(source["state"], "running");
    ASSERT_EQ(source["cameras"].size(), 2u);
    EXPECT_EQ(source["cameras"][0]["name"], "/stereo/left/image_raw");
    EXPECT_EQ(source["cameras"][1]["name"], "/stereo/right/image_raw");
    EXPECT_GT(source["pairs"].get<int>(), 0);
    EXPECT_EQ(source["cameras"][0]["bad_frames"], 0);
    // Both images of a pair carry one stamp.
    EXPECT_EQ(source["skew_ms"]["max"].get<double>(), 0.0);
}

// Colour drivers (rgb8, bgr8) are matched as grey; a reliable writer is taken too.
TEST_F(Ros2Source, ColourImagesFromAReliableWriterAreMatchedAsGrey)
{
    const double replayed = replayedDistance();
    ASSERT_GT(replayed, 0.0);
    startRos2Service();
    ASSERT_FALSE(HasFailure());
    for (const std::string encoding : {"rgb8", "bgr8"}) {
        publish(60, {"--encoding", encoding, "--reliable"});
        // A reading of this publisher's pairs: the previous one's are a second old.
        std::this_thread::sleep_for(1500ms);
        const Json reading = waitForReading(valid, 30s);
        ASSERT_TRUE(valid(reading)) << encoding << ": " << reading.dump();
        // The grey of cvtColor and libpng's differ by a level here and there.
        EXPECT_NEAR(reading["distance_m"].get<double>(), replayed, 0.01 * replayed) << encoding;
        EXPECT_EQ(status()["source"]["cameras"][0]["bad_frames"], 0) << encoding;
        publisher_.reset();
    }
}

// A driver's YUV 4:2:2 (UYVY as ROS's yuv422, YUYV as yuv422_yuy2) is matched on its
// luma: the files' grey as luma gives the replayed distance exactly. An odd width cannot
// be 4:2:2 and is refused by name.
TEST_F(Ros2Source, Yuv422IsMatchedOnItsLumaAndAnOddWidthIsRefused)
{
    const double replayed = replayedDistance();
    ASSERT_GT(replayed, 0.0);
    startRos2Service();
    ASSERT_FALSE(HasFailure());
    for (const std::string encoding : {"yuv422", "yuv422_yuy2"}) {
        publish(60, {"--encoding", encoding});
        // A reading of this publisher's pairs: the previous one's are a second old.
        std::this_thread::sleep_for(1500ms);
        const Json reading = waitForReading(valid, 30s);
        ASSERT_TRUE(valid(reading)) << encoding << ": " << reading.dump();
        EXPECT_DOUBLE_EQ(reading["distance_m"].get<double>(), replayed) << encoding;
        EXPECT_EQ(status()["source"]["cameras"][0]["bad_frames"], 0) << encoding;
        publisher_.reset();
    }

    publish(60, {"--encoding", "yuv422", "--width", "383"});
    const Json left = leftOnceBadTwice();
    EXPECT_GE(left["bad_frames"].get<int>(), 2) << left.dump();
    EXPECT_EQ(left["last_bad_frame"],
              "image of 383x288 yuv422 has an odd width: 4:2:2 pixels come in pairs");
}

TEST_F(Ros2Source, StampsFurtherApartThanMaxSkewAreNotPaired)
{
    startRos2Service("  max_skew_ms: 5\n");
    ASSERT_FALSE(HasFailure());
    publish(60, {"--right-offset-ms", "20"});
    // Both topics arrive, no pair is made.
    Json source;
    const auto deadline = std::chrono::steady_clock::now() + 30s;
    while (std::chrono::steady_clock::now() < deadline) {
        source = status()["source"];
        if (source["cameras"][0]["frames"].get<int>() >= 10 &&
            source["cameras"][1]["frames"].get<int>() >= 10)
            break;
        std::this_thread::sleep_for(200ms);
    }
    ASSERT_GE(source["cameras"][1]["frames"].get<int>(), 10) << source.dump();
    EXPECT_EQ(source["pairs"], 0) << source.dump();
    EXPECT_GE(source["unpaired_dropped"].get<int>(), 10) << source.dump();
    const Json reading = distance();
    EXPECT_FALSE(valid(reading)) << reading.dump();
}

TEST_F(Ros2Source, AMalformedImageIsRefusedWithItsMessageAndTheServiceRunsOn)
{
    startRos2Service();
    ASSERT_FALSE(HasFailure());
    // Every third left image declares a step of 192 bytes for its rows of 384.
    publish(60, {"--bad-every", "3"});
    const Json reading = waitForReading(valid, 30s);
    ASSERT_TRUE(valid(reading)) << reading.dump();
    const Json left = leftOnceBadTwice();
    EXPECT_GE(left["bad_frames"].get<int>(), 2) << left.dump();
    EXPECT_EQ(left["last_bad_frame"],
              "image of 384x288 mono8 has step 192, less than its row of 384 bytes");
    // The good two of every three images keep coming (the first may be lost to discovery).
    EXPECT_GE(left["frames"].get<int>(), left["bad_frames"].get<int>());
    // Still serving readings of the good pairs after the bad ones.
    std::this_thread::sleep_for(500ms);
    EXPECT_TRUE(valid(waitForReading(valid, 10s)));
}

TEST_F(Ros2Source, APublisherGoneIsSourceDownAndReadingsResumeWhenItIsBack)
{
    startRos2Service();
    ASSERT_FALSE(HasFailure());
    publish(4);
    ASSERT_TRUE(valid(waitForReading(valid, 30s)));
    ASSERT_TRUE(publisher_->waitFor(30s).has_value());

    // No image for stall_timeout_ms (1 s): source down, naming the topic.
    const Json down =
        waitForReading([](const Json& r) { return reasonCode(r) == "source_down"; }, 20s);
    EXPECT_EQ(reasonCode(down), "source_down") << down.dump();
    const Json st = status();
    EXPECT_EQ(st["state"], "source_down");
    EXPECT_EQ(st["source"]["state"], "stalled");
    // Both publishers stopped at once: whichever topic passed the timeout first is named.
    const std::string error = st["source"]["last_error"];
    EXPECT_TRUE(error.find("no image on /stereo/left/image_raw") != std::string::npos ||
                error.find("no image on /stereo/right/image_raw") != std::string::npos)
        << st["source"].dump();

    publish(60);
    const Json back = waitForReading(valid, 30s);
    EXPECT_TRUE(valid(back)) << back.dump();
    EXPECT_EQ(status()["source"]["state"], "running");
}

TEST_F(Ros2Source, CalibrationFromTheDriversCameraInfoGivesTheFileCalibratedDistance)
{
    const double replayed = replayedDistance();
    ASSERT_GT(replayed, 0.0);
    const auto [left_info, right_info] = exportCameraInfo();
    startRos2Service({}, {}, false);
    ASSERT_FALSE(HasFailure());
    // Images without camera_info: uncalibrated, and the status says what it waits for.
    publish(60);
    const Json waiting =
        waitForReading([](const Json& r) { return reasonCode(r) == "uncalibrated"; }, 30s);
    EXPECT_EQ(reasonCode(waiting), "uncalibrated") << waiting.dump();
    const Json warnings =
        waitForWarning("waiting for camera_info on /stereo/left/camera_info", 10s);
    EXPECT_NE(warnings.dump().find("waiting for camera_info on /stereo/left/camera_info (0 "
                                   "publishers) and /stereo/right/camera_info (0 publishers)"),
              std::string::npos)
        << warnings.dump();
    EXPECT_EQ(status()["state"], "uncalibrated");

    // The driver with its camera_info (reliable, as the images then): processing starts,
    // and the distance is the file-calibrated one.
    publisher_.reset();
    publish(60, {"--camera-info", left_info, right_info, "--reliable"});
    const Json reading = waitForReading(valid, 30s);
    ASSERT_TRUE(valid(reading)) << reading.dump();
    EXPECT_DOUBLE_EQ(reading["distance_m"].get<double>(), replayed);
    const Json st = status();
    EXPECT_EQ(st["state"], "running");
    EXPECT_EQ(st["calibration"]["path"], "/stereo/left/camera_info + /stereo/right/camera_info")
        << st["calibration"].dump();
    EXPECT_NEAR(st["calibration"]["focal_px"].get<double>(), test::kTsukubaFocalPx, 1e-9)
        << st["calibration"].dump();
    EXPECT_EQ(st["source"]["warnings"].size(), 0u) << st["source"].dump();
}

TEST_F(Ros2Source, AMalformedCameraInfoIsRefusedByTopicAndFieldAndTheServiceRunsOn)
{
    const auto [left_info, right_info] = exportCameraInfo();
    // The right camera's model one stereod cannot undistort with.
    std::ifstream in(right_info);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string model = "distortion_model: plumb_bob";
    ASSERT_NE(text.find(model), std::string::npos) << text;
    text.replace(text.find(model), model.size(), "distortion_model: equidistant");
    std::ofstream(right_info) << text;

    startRos2Service({}, {}, false);
    ASSERT_FALSE(HasFailure());
    publish(60, {"--camera-info", left_info, right_info});
    const std::string refusal =
        "camera_info refused: /stereo/right/camera_info: distortion_model: 'equidistant' is not "
        "supported";
    const Json warnings = waitForWarning(refusal, 30s);
    EXPECT_NE(warnings.dump().find(refusal), std::string::npos) << warnings.dump();
    // Still running, on images, uncalibrated.
    const Json reading = distance();
    EXPECT_EQ(reasonCode(reading), "uncalibrated") << reading.dump();
    const Json st = status();
    EXPECT_EQ(st["state"], "uncalibrated");
    EXPECT_EQ(st["source"]["state"], "running");
    EXPECT_GT(st["source"]["pairs"].get<int>(), 0);
}

// In the ROS 2 graph the source is a node with its four subscriptions: its participant's
// ros_discovery_info, as a Fast DDS peer decodes it, names /stereo/stereod_source with the
// GIDs of the readers discovery finds on the image and camera_info topics.
TEST_F(Ros2Source, ItsSubscriptionsAreAnnouncedAsANodeOnRosDiscoveryInfo)
{
    const auto [left_info, right_info] = exportCameraInfo();
    startRos2Service({}, {}, false);
    ASSERT_FALSE(HasFailure());
    publish(60, {"--camera-info", left_info, right_info});
    // Four seconds of the domain (no stereod topic comes: the node does not publish).
    const test::ProcessResult peer =
        test::runProcess({STEREOD_FASTDDS_SUBSCRIBER, domain_.text(), "/stereo", "4", "1"});
    ASSERT_EQ(peer.exit_code, 0) << peer.err;
    const Json result = Json::parse(peer.out);
    SCOPED_TRACE(result.dump());

    const Json& samples = result["topics"]["ros_discovery_info"]["last"];
    ASSERT_TRUE(samples.is_array());
    const Json* node = nullptr;
    std::string participant;
    for (const Json& sample : samples)
        for (const Json& candidate : sample["nodes"])
            if (candidate["name"] == "stereod_source") {
                node = &candidate;
                participant = sample["gid"];
            }
    ASSERT_NE(node, nullptr);
    EXPECT_EQ((*node)["namespace"], "/stereo");
    EXPECT_TRUE((*node)["writers"].empty());
    const Json& readers = (*node)["readers"];
    ASSERT_EQ(readers.size(), 4u);
    ASSERT_EQ(participant.size(), 32u);
    for (const Json& reader : readers)
        EXPECT_EQ(reader.get<std::string>().substr(0, 24), participant.substr(0, 24));
    // Each topic's reader, as the peer's discovery saw it, is one the node announces.
    for (const std::string topic : {"rt/stereo/left/image_raw", "rt/stereo/right/image_raw",
                                    "rt/stereo/left/camera_info", "rt/stereo/right/camera_info"}) {
        const Json& found = result["discovered_readers"][topic];
        int announced = 0;
        for (const Json& guid : found)
            announced += std::count(readers.begin(), readers.end(), guid) > 0 ? 1 : 0;
        EXPECT_EQ(announced, 1) << topic << ": " << found.dump();
    }
}

} // namespace
} // namespace stereod
