#pragma once
// What the V4L2 capture tests share: a scratch directory with test images cut from a real
// photograph, and fake V4L2 devices described in it (tests/fake_v4l2/fake_v4l2.hpp).

#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <unistd.h>

#include "capture/v4l2_camera.hpp"
#include "tests/fake_v4l2/fake_v4l2.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod::test {

inline constexpr const char* kFakeLeft = "/dev/video-fake-left";
inline constexpr const char* kFakeRight = "/dev/video-fake-right";
inline constexpr const char* kFakeLeftById = "usb-Fake_Stereo_Left_0001-video-index0";
inline constexpr int kWidth = 320;
inline constexpr int kHeight = 240;

// A fixture with a scratch directory holding `scene.png`: 320x240 grayscale, cut from
// OpenCV's Aloe photograph, so that every format the fake serves is a real image.
class FakeCameraTest : public ::testing::Test {
  protected:
    void SetUp() override
    {
        dir_ = std::filesystem::temp_directory_path() /
               ("stereod_capture_" + std::to_string(::getpid()) + "_" +
                ::testing::UnitTest::GetInstance()->current_test_info()->name());
        std::filesystem::create_directories(dir_);
        const cv::Mat aloe =
            cv::imread(test::opencvSamplesDir() + "/aloeL.jpg", cv::IMREAD_GRAYSCALE);
        ASSERT_FALSE(aloe.empty()) << "OpenCV sample aloeL.jpg missing";
        cv::resize(aloe, scene_, cv::Size(kWidth, kHeight), 0, 0, cv::INTER_AREA);
        ASSERT_TRUE(cv::imwrite((dir_ / "scene.png").string(), scene_));
    }

    void TearDown() override
    {
        stereod_fake_v4l2_unload();
        std::filesystem::remove_all(dir_);
    }

    // Loads a description of the left device (and `more` devices, YAML list items)
    // offering `formats` (YAML list items under `formats:`), serving scene.png.
    void loadFake(const std::string& formats, const std::string& device_extra = "",
                  const std::string& more = "")
    {
        const std::filesystem::path file = dir_ / "devices.yaml";
        std::ofstream(file) << "devices:\n"
                            << "  - path: " << kFakeLeft << "\n"
                            << "    by_id: " << kFakeLeftById << "\n"
                            << "    card: Fake Stereo Left\n"
                            << "    images: " << (dir_ / "scene.png").string() << "\n"
                            << "    fps: [100, 30]\n"
                            << "    jpeg_quality: 90\n"
                            << "    formats:\n"
                            << formats << device_extra << more;
        ASSERT_EQ(stereod_fake_v4l2_load(file.c_str()), 0) << stereod_fake_v4l2_last_error();
    }

    CameraSettings settings(PixelFormatChoice format, double fps = 100.0) const
    {
        CameraSettings s;
        s.device = kFakeLeft;
        s.format = format;
        s.width = kWidth;
        s.height = kHeight;
        s.fps = fps;
        return s;
    }

    std::filesystem::path dir_;
    cv::Mat scene_; // what every frame shows, CV_8UC1
};

// The next frame from `ring`, or nothing after `timeout` (a guard against hangs, not a
// timing assertion).
inline std::optional<CapturedFrame>
nextFrame(CapturedRing& ring, std::chrono::milliseconds timeout = std::chrono::seconds(5))
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
        if (std::optional<CapturedFrame> frame = ring.tryPop())
            return frame;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return std::nullopt;
}

// Waits until `predicate()` holds, up to `timeout` (a guard, as above).
template <typename Predicate>
bool waitFor(Predicate predicate, std::chrono::milliseconds timeout = std::chrono::seconds(5))
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!predicate()) {
        if (std::chrono::steady_clock::now() >= deadline)
            return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return true;
}

} // namespace stereod::test
