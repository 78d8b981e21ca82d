// stereod on cameras, as a separate process: the fake V4L2 device (tests/fake_v4l2) is
// preloaded into the unchanged stereod and serves Middlebury tsukuba as two cameras (GREY,
// YUYV, MJPEG) or one side-by-side camera. The distance equals the offline reading of the
// same images; `status` shows the cameras and the pairing skew; a camera unplugged under
// the running service turns readings into source_down with the reason while the service
// keeps answering, and depth comes back after the replug.

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <signal.h>
#include <unistd.h>

#include "ctl/client.hpp"
#include "pipeline/calibration.hpp"
#include "replay/image_message.hpp"
#include "replay/mcap_reader.hpp"
#include "replay/mcap_recording.hpp"
#include "ros2/messages.hpp"
#include "tests/fake_v4l2/fake_v4l2.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;
using Json = nlohmann::ordered_json;
using test::ChildProcess;
using test::ProcessResult;
using test::runProcess;

const std::string kTsukuba = test::tsukubaDir();
constexpr const char* kLeft = "/dev/video-e2e-left";
constexpr const char* kRight = "/dev/video-e2e-right";
constexpr const char* kSideBySide = "/dev/video-e2e-sbs";
// Liveness bounds, generous for sanitizer builds: reaching them means "never happened".
constexpr auto kStartLimit = 60s;
constexpr auto kEventLimit = 30s;

class StereodCamerasE2e : public ::testing::Test {
  protected:
    void SetUp() override
    {
        left_ = dir_.file("left.png");
        right_ = dir_.file("right.png");
        std::filesystem::copy_file(kTsukuba + "/im3.png", left_);
        std::filesystem::copy_file(kTsukuba + "/im4.png", right_);
        const cv::Mat left = cv::imread(left_, cv::IMREAD_GRAYSCALE);
        const cv::Mat right = cv::imread(right_, cv::IMREAD_GRAYSCALE);
        ASSERT_FALSE(left.empty());
        size_ = left.size();
        cv::Mat whole;
        cv::hconcat(left, right, whole);
        ASSERT_TRUE(cv::imwrite(dir_.file("sbs.png"), whole));
        calibration_ = dir_.file("calib.yaml");
        saveCalibration(
            makeRectifiedCalibration(size_, test::kTsukubaFocalPx, test::kTsukubaBaselineM),
            calibration_);
        socket_ = dir_.file("s.sock");
        log_ = dir_.file("stereod.log");
        fifo_ = dir_.file("fake.fifo");
    }

    void TearDown() override
    {
        if (service_ && service_->running()) {
            service_->sendSignal(SIGTERM);
            service_->waitFor(10s);
        }
        if (HasFailure())
            std::cerr << "--- stereod log ---\n" << serviceLog() << "------------------\n";
    }

    std::string sizeText() const
    {
        return std::to_string(size_.width) + "x" + std::to_string(size_.height);
    }

    std::string sideBySideSizeText() const
    {
        return std::to_string(2 * size_.width) + "x" + std::to_string(size_.height);
    }

    // Describes the fake devices and starts stereod on them with `source_yaml` (the
    // `source:` section).
    void startService(const std::string& devices_yaml, const std::string& source_yaml)
    {
        const std::string description = dir_.file("devices.yaml");
        std::ofstream(description) << "control: " << fifo_ << "\nseed: 3\ndevices:\n"
                                   << devices_yaml;
        const std::string config = dir_.file("stereod.yaml");
        std::ofstream(config) << source_yaml << "calibration: " << calibration_
                              << "\nsocket:\n  path: " << socket_ << "\n";

        // The child gets the fake preloaded; this process must not (it would serve the
        // same devices and read the same control FIFO), so the environment is restored
        // right after the start.
        std::vector<std::pair<std::string, std::optional<std::string>>> saved;
        for (const std::string& entry :
             fake_v4l2::childEnvironment(STEREOD_FAKE_V4L2_LIBRARY, description)) {
            const std::string name = entry.substr(0, entry.find('='));
            const char* old = std::getenv(name.c_str());
            saved.emplace_back(name,
                               old != nullptr ? std::optional<std::string>(old) : std::nullopt);
            ::setenv(name.c_str(), entry.substr(name.size() + 1).c_str(), 1);
        }
        service_ = std::make_unique<ChildProcess>(
            std::vector<std::string>{test::stereodPath(), "--config", config}, log_);
        for (const auto& [name, value] : saved) {
            if (value)
                ::setenv(name.c_str(), value->c_str(), 1);
            else
                ::unsetenv(name.c_str());
        }
    }

    // `right_extra`: more keys of the right camera's description (phase_ms, ...).
    static std::string cameraDevices(const std::string& fourcc, const std::string& right_extra = {})
    {
        std::ostringstream out;
        for (const char* path : {kLeft, kRight}) {
            out << "  - path: " << path << "\n"
                << "    images: " << (path == kLeft ? "LEFT" : "RIGHT") << "\n"
                << "    fps: [15]\n"
                << "    jitter_ms: 0.5\n"
                << "    formats:\n      - { fourcc: " << fourcc << ", sizes: [SIZE] }\n"
                << (path == kRight ? right_extra : std::string());
        }
        return out.str();
    }

    std::string withPaths(std::string yaml) const
    {
        const auto replace = [&](const std::string& from, const std::string& to) {
            for (std::size_t at = yaml.find(from); at != std::string::npos;
                 at = yaml.find(from, at + to.size()))
                yaml.replace(at, from.size(), to);
        };
        replace("LEFT", left_);
        replace("RIGHT", right_);
        replace("SBSIZE", sideBySideSizeText());
        replace("SIZE", sizeText());
        return yaml;
    }

    std::string cameraSource(const std::string& format) const
    {
        return "source:\n  type: v4l2\n  max_skew_ms: 5\n  cameras:\n    left: " +
               std::string(kLeft) + "\n    right: " + kRight + "\n    format: " + format +
               "\n    width: " + std::to_string(size_.width) +
               "\n    height: " + std::to_string(size_.height) + "\n    fps: 15\n";
    }

    std::string serviceLog() const
    {
        std::ifstream in(log_);
        std::stringstream text;
        text << in.rdbuf();
        return text.str();
    }

    Json request(const Json& request) const
    {
        ProtocolClient client(socket_, 5000ms);
        return client.request(request);
    }

    // The reading of `distance` once it satisfies `done`, or fails the test.
    template <typename Done> Json waitForReading(Done done, const char* what)
    {
        const auto deadline = std::chrono::steady_clock::now() + kStartLimit;
        std::string last;
        while (std::chrono::steady_clock::now() < deadline) {
            if (!service_->running()) {
                ADD_FAILURE() << "stereod exited:\n" << serviceLog();
                return Json();
            }
            try {
                Json reading = request({{"cmd", "distance"}})["reading"];
                if (done(reading))
                    return reading;
                last = reading.dump();
            } catch (const std::exception& e) {
                last = e.what();
            }
            std::this_thread::sleep_for(20ms);
        }
        ADD_FAILURE() << "never " << what << "; last: " << last;
        return Json();
    }

    Json waitForDistance()
    {
        return waitForReading([](Json& r) { return r.value("valid", false); }, "a valid distance");
    }

    // The offline reading of the same pair through `stereoctl depth`.
    double offlineDistance() const
    {
        const ProcessResult offline = runProcess(
            {test::stereoctlPath(), "depth", left_, right_, "--calib", calibration_, "--json"});
        EXPECT_EQ(offline.exit_code, 0) << offline.err;
        return Json::parse(offline.out)["reading"]["distance_m"].get<double>();
    }

    // Sends a command to the fake inside stereod through its control FIFO.
    void fakeCommand(const std::string& line) const
    {
        const auto deadline = std::chrono::steady_clock::now() + kEventLimit;
        int fd = -1;
        while ((fd = ::open(fifo_.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC)) < 0 &&
               std::chrono::steady_clock::now() < deadline)
            std::this_thread::sleep_for(10ms); // ENXIO until the fake reads the FIFO
        ASSERT_GE(fd, 0) << "cannot open the fake's control FIFO " << fifo_;
        const std::string text = line + "\n";
        EXPECT_EQ(::write(fd, text.data(), text.size()), static_cast<ssize_t>(text.size()));
        ::close(fd);
    }

    test::TempDir dir_;
    std::string left_, right_, calibration_, socket_, log_, fifo_;
    cv::Size size_;
    std::unique_ptr<ChildProcess> service_;
};

// Each pixel format, end to end to the distance: equal to the offline reading of the
// same images (MJPEG within its compression loss).
TEST_F(StereodCamerasE2e, EachPixelFormatGivesTheOfflineDistance)
{
    const double offline_m = offlineDistance();
    const struct {
        const char* fourcc;
        const char* format;
        double tolerance_m;
    } cases[] = {{"GREY", "grey", 0.0015}, {"YUYV", "yuyv", 0.0015}, {"MJPG", "mjpeg", 0.02}};
    for (const auto& c : cases) {
        SCOPED_TRACE(c.format);
        startService(withPaths(cameraDevices(c.fourcc)), cameraSource(c.format));
        Json reading = waitForDistance();
        ASSERT_TRUE(reading.is_object());
        EXPECT_NEAR(reading["distance_m"].get<double>(), offline_m, c.tolerance_m);

        Json status = request({{"cmd", "status"}})["status"];
        Json source = status["source"];
        EXPECT_EQ(source["kind"], "v4l2");
        EXPECT_EQ(source["state"], "running");
        ASSERT_EQ(source["cameras"].size(), 2u);
        EXPECT_EQ(source["cameras"][0]["name"], "left");
        EXPECT_EQ(source["cameras"][1]["state"], "running");
        EXPECT_GT(source["pairs"].get<uint64_t>(), 0u);
        EXPECT_LE(source["skew_ms"]["max"].get<double>(), 5.0);
        EXPECT_FALSE(source["clock_offset"]["detected"].get<bool>());

        // Only that it ends: the clean exit status on SIGTERM is checked by
        // tests/ctl/e2e_test.cpp; here the preloaded fake's own threads may take the signal.
        service_->sendSignal(SIGTERM);
        ASSERT_TRUE(service_->waitFor(10s).has_value()) << serviceLog();
        service_.reset();
    }
}

// A colour camera's colour reaches the outputs: `stereoctl snapshot` writes the rectified
// left image in colour (tsukuba's own colours, within YUYV's shared chroma) and a PLY
// coloured point by point; with `colour: none` the same cameras give the grey image, as
// before colour.
TEST_F(StereodCamerasE2e, ColourCamerasGiveAColourLeftImageAndCloud)
{
    const cv::Mat photograph = cv::imread(left_, cv::IMREAD_COLOR);
    ASSERT_FALSE(photograph.empty());
    for (const bool keep : {true, false}) {
        SCOPED_TRACE(keep ? "colour: left" : "colour: none");
        startService(withPaths(cameraDevices("YUYV")),
                     cameraSource("yuyv") + (keep ? "" : "    colour: none\n"));
        ASSERT_TRUE(waitForDistance().is_object());
        const std::string left_png = dir_.file(keep ? "snap-colour.png" : "snap-grey.png");
        const std::string cloud_ply = dir_.file(keep ? "snap-colour.ply" : "snap-grey.ply");
        const ProcessResult snapshot =
            runProcess({test::stereoctlPath(), "snapshot", "--socket", socket_, "--left", left_png,
                        "--cloud", cloud_ply});
        ASSERT_EQ(snapshot.exit_code, 0) << snapshot.err;
        const cv::Mat written = cv::imread(left_png, cv::IMREAD_UNCHANGED);
        ASSERT_EQ(written.size(), size_);
        std::ifstream ply(cloud_ply);
        std::stringstream ply_text;
        ply_text << ply.rdbuf();
        const bool coloured_ply = ply_text.str().find("property uchar red") != std::string::npos;
        if (keep) {
            // A rectified-only calibration: the rectified image is the captured one.
            ASSERT_EQ(written.type(), CV_8UC3);
            cv::Mat diff;
            cv::absdiff(written, photograph, diff);
            const cv::Scalar mean = cv::mean(diff);
            EXPECT_LT((mean[0] + mean[1] + mean[2]) / 3.0, 4.0);
            EXPECT_TRUE(coloured_ply) << snapshot.out;

            // Recorded as captured: the bag's left image is bgr8, the camera's colour; the
            // right camera (colour: left) stays mono8.
            const std::string bag = dir_.file("colour.mcap");
            const ProcessResult record = runProcess({test::stereoctlPath(), "record", "--socket",
                                                     socket_, "--out", bag, "--frames", "2"});
            ASSERT_EQ(record.exit_code, 0) << record.err;
            mcap::Reader reader(bag);
            const McapStereoIndex index = indexMcapStereo(reader, "", "");
            ASSERT_FALSE(index.pairs.empty());
            // A message's data lasts until the reader's next call: copied.
            const std::string left_message(reader.message(index.pairs[0].left).data);
            EXPECT_EQ(ros2::parseImage(left_message).encoding, "bgr8");
            EXPECT_EQ(ros2::parseImage(reader.message(index.pairs[0].right).data).encoding,
                      "mono8");
            cv::Mat grey;
            cv::Mat colour;
            std::string why;
            ASSERT_TRUE(decodeImageMessage(left_message, size_, grey, colour, why)) << why;
            cv::absdiff(colour, photograph, diff);
            const cv::Scalar bag_mean = cv::mean(diff);
            EXPECT_LT((bag_mean[0] + bag_mean[1] + bag_mean[2]) / 3.0, 4.0);
        } else {
            EXPECT_EQ(written.type(), CV_8UC1);
            EXPECT_FALSE(coloured_ply) << snapshot.out;
        }
        service_->sendSignal(SIGTERM);
        ASSERT_TRUE(service_->waitFor(10s).has_value()) << serviceLog();
        service_.reset();
    }
}

TEST_F(StereodCamerasE2e, SideBySideCameraGivesTheOfflineDistance)
{
    const double offline_m = offlineDistance();
    startService(withPaths("  - path: " + std::string(kSideBySide) +
                           "\n    images: " + dir_.file("sbs.png") +
                           "\n    fps: [15]\n    formats:\n      - { fourcc: YUYV, sizes: "
                           "[SBSIZE] }\n"),
                 "source:\n  type: side_by_side\n  cameras:\n    device: " +
                     std::string(kSideBySide) + "\n    width: " + std::to_string(2 * size_.width) +
                     "\n    height: " + std::to_string(size_.height) + "\n    fps: 15\n");
    Json reading = waitForDistance();
    ASSERT_TRUE(reading.is_object());
    EXPECT_NEAR(reading["distance_m"].get<double>(), offline_m, 0.0015);
    Json source = request({{"cmd", "status"}})["status"]["source"];
    EXPECT_EQ(source["kind"], "side-by-side");
    EXPECT_EQ(source["state"], "running");
}

// A camera unplugged under the running service: `distance` says source_down with the
// camera and the reason, `status` shows it, the service keeps answering; after the
// replug the camera is reopened and valid readings come back.
TEST_F(StereodCamerasE2e, UnpluggedCameraGivesSourceDownUntilReplugged)
{
    startService(withPaths(cameraDevices("YUYV")), cameraSource("auto"));
    Json before = waitForDistance();
    ASSERT_TRUE(before.is_object());

    fakeCommand(std::string("unplug ") + kRight);
    Json down = waitForReading(
        [](Json& r) {
            return !r.value("valid", true) &&
                   r.value("reason", Json::object()).value("code", "") == "source_down";
        },
        "source_down after the unplug");
    ASSERT_TRUE(down.is_object());
    const std::string message = down["reason"].value("message", "");
    EXPECT_NE(message.find("right camera"), std::string::npos) << down.dump();
    Json source = request({{"cmd", "status"}})["status"]["source"];
    EXPECT_EQ(source["state"], "failed") << source.dump();
    EXPECT_EQ(source["cameras"][1]["state"], "failed");
    EXPECT_EQ(source["cameras"][0]["state"], "running");
    EXPECT_NE(source["last_error"].get<std::string>().find(kRight), std::string::npos)
        << source.dump();
    // The CLI tells the robot the same, with the exit code of "not producing".
    const ProcessResult ctl = runProcess({test::stereoctlPath(), "distance", "--socket", socket_});
    EXPECT_EQ(ctl.exit_code, 2) << ctl.out << ctl.err;

    fakeCommand(std::string("replug ") + kRight);
    const uint64_t frame_before = before["frame"].get<uint64_t>();
    Json after = waitForReading(
        [&](Json& r) {
            return r.value("valid", false) && r.value("frame", uint64_t{0}) > frame_before;
        },
        "a valid distance after the replug");
    ASSERT_TRUE(after.is_object());
    EXPECT_NEAR(after["distance_m"].get<double>(), before["distance_m"].get<double>(), 0.0015);
    EXPECT_EQ(request({{"cmd", "status"}})["status"]["source"]["state"], "running");
}

// A camera that sends nothing but bad frames for seconds on end: the service keeps
// running, `status` counts them with the reason and says the camera gives no good frame
// (not "no frame"), readings come back valid afterwards, and the journal gets one line
// per camera per 5 s, not one per frame.
TEST_F(StereodCamerasE2e, CorruptFramesAreCountedAndLoggedOncePerInterval)
{
    startService(withPaths(cameraDevices("MJPG")), cameraSource("mjpeg"));
    ASSERT_TRUE(waitForDistance().is_object());
    const auto start = std::chrono::steady_clock::now();
    fakeCommand(std::string("corrupt ") + kRight + " 90 truncated"); // 6 s at 15 fps

    Json camera;
    bool said_no_good_frame = false;
    const auto deadline = start + kEventLimit;
    while (std::chrono::steady_clock::now() < deadline) {
        camera = request({{"cmd", "status"}})["status"]["source"]["cameras"][1];
        const std::string error = camera.value("last_error", std::string());
        said_no_good_frame |= error.find("no good frame for") != std::string::npos &&
                              error.find("bad (latest: ") != std::string::npos;
        EXPECT_EQ(error.find("no frame for"), std::string::npos) << error;
        if (camera.value("bad_frames", uint64_t{0}) >= 90)
            break;
        std::this_thread::sleep_for(100ms);
    }
    EXPECT_EQ(camera.value("bad_frames", uint64_t{0}), 90u) << camera.dump();
    EXPECT_FALSE(camera.value("last_bad_frame", std::string()).empty()) << camera.dump();
    EXPECT_TRUE(said_no_good_frame) << serviceLog();
    const Json after = waitForReading([](Json& r) { return r.value("valid", false); },
                                      "a valid distance after the bad frames");
    EXPECT_TRUE(after.is_object());

    // Every bad frame is in some line, and the lines are no more than one per 5 s.
    std::this_thread::sleep_for(5500ms);
    const double elapsed_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::istringstream log(serviceLog());
    int lines = 0;
    uint64_t counted = 0;
    for (std::string line; std::getline(log, line);) {
        const std::size_t at = line.find("camera right: ");
        if (at == std::string::npos || line.find("bad frame") == std::string::npos)
            continue;
        ++lines;
        counted += std::stoull(line.substr(at + 14));
        EXPECT_NE(line.find("latest: "), std::string::npos) << line;
    }
    EXPECT_EQ(counted, 90u) << serviceLog();
    EXPECT_GE(lines, 1);
    EXPECT_LE(lines, static_cast<int>(elapsed_s / 5.0) + 2) << serviceLog();
}

// The right camera captures 12 ms after the left, beyond max_skew 5 ms: no pair is made of
// frames that far apart, so there is no reading, and `stereoctl status` names the offset
// instead of leaving a person to guess why.
TEST_F(StereodCamerasE2e, ClockOffsetBetweenTheCamerasIsShownNotAbsorbed)
{
    startService(withPaths(cameraDevices("YUYV", "    phase_ms: 12\n")), cameraSource("auto"));
    Json source;
    const auto deadline = std::chrono::steady_clock::now() + kStartLimit;
    while (std::chrono::steady_clock::now() < deadline) {
        try {
            source = request({{"cmd", "status"}})["status"]["source"];
            if (source["clock_offset"].value("detected", false))
                break;
        } catch (const ClientError&) {
            // not listening yet
        }
        std::this_thread::sleep_for(50ms);
    }
    ASSERT_TRUE(source["clock_offset"].value("detected", false)) << source.dump();
    EXPECT_NEAR(source["clock_offset"]["estimate_ms"].get<double>(), 12.0, 1.5);
    EXPECT_EQ(source["pairs"], 0u);

    const ProcessResult status = runProcess({test::stereoctlPath(), "status", "--socket", socket_});
    EXPECT_EQ(status.exit_code, 0) << status.err;
    EXPECT_NE(status.out.find("clock offset between the cameras: right - left = 1"),
              std::string::npos)
        << status.out;
    EXPECT_NE(status.out.find("  warning: "), std::string::npos) << status.out;
    EXPECT_NE(status.out.find("unpaired"), std::string::npos) << status.out;

    const ProcessResult distance =
        runProcess({test::stereoctlPath(), "distance", "--socket", socket_, "--json"});
    EXPECT_NE(distance.exit_code, 0) << distance.out;
    EXPECT_FALSE(Json::parse(distance.out).value("valid", true)) << distance.out;
}

} // namespace
} // namespace stereod
