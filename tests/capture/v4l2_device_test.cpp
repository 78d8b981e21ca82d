// The V4L2 device layer against the fake device, through libv4l2: format negotiation with
// `auto` and its refusals, frame rates, controls applied and read back, and the device
// listing of `stereoctl devices`.

#include <algorithm>
#include <cerrno>
#include <string>

#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <nlohmann/json.hpp>

#include "capture/device_list.hpp"
#include "capture/v4l2_device.hpp"
#include "tests/support/fake_cameras.hpp"

namespace stereod {
namespace {

using test::FakeCameraTest;
using test::kFakeLeft;
using test::kHeight;
using test::kWidth;

const ControlReading* findControl(const std::vector<ControlReading>& readings,
                                  const std::string& name)
{
    const auto it = std::find_if(readings.begin(), readings.end(),
                                 [&](const ControlReading& r) { return r.name == name; });
    return it == readings.end() ? nullptr : &*it;
}

class V4l2DeviceTest : public FakeCameraTest {
  protected:
    NegotiatedFormat negotiate(const CameraSettings& s, int expected_rc = 0)
    {
        V4l2Device device;
        EXPECT_EQ(device.open(s.device), 0) << device.errorText();
        NegotiatedFormat format;
        const int rc = device.negotiate(s, format);
        EXPECT_EQ(rc, expected_rc) << device.errorText();
        error_ = device.errorText();
        return format;
    }

    std::string error_;
};

TEST_F(V4l2DeviceTest, OpenRefusesMissingDevice)
{
    loadFake("      - { fourcc: YUYV, sizes: [320x240] }\n");
    V4l2Device device;
    EXPECT_EQ(device.open("/dev/video-fake-absent"), -ENOENT);
    EXPECT_NE(device.errorText().find("/dev/video-fake-absent"), std::string::npos)
        << device.errorText();
    EXPECT_FALSE(device.isOpen());
}

TEST_F(V4l2DeviceTest, OpenReadsIdentity)
{
    loadFake("      - { fourcc: YUYV, sizes: [320x240] }\n");
    V4l2Device device;
    ASSERT_EQ(device.open(kFakeLeft), 0) << device.errorText();
    EXPECT_EQ(device.identity().card, "Fake Stereo Left");
    EXPECT_EQ(device.identity().driver, "uvcvideo");
    EXPECT_NE(device.identity().device_caps & V4L2_CAP_VIDEO_CAPTURE, 0u);
}

TEST_F(V4l2DeviceTest, AutoPrefersGreyThenYuyvThenMjpeg)
{
    loadFake("      - { fourcc: MJPG, sizes: [320x240] }\n"
             "      - { fourcc: YUYV, sizes: [320x240] }\n"
             "      - { fourcc: GREY, sizes: [320x240] }\n");
    NegotiatedFormat format = negotiate(settings(PixelFormatChoice::Auto));
    EXPECT_EQ(format.fourcc, V4L2_PIX_FMT_GREY);
    EXPECT_EQ(format.bytes_per_line, static_cast<uint32_t>(kWidth));
    EXPECT_NE(format.reason.find("auto chose GREY"), std::string::npos) << format.reason;

    // GREY offered, but not at the asked size: YUYV, and the reason says why not GREY.
    loadFake("      - { fourcc: GREY, sizes: [640x480] }\n"
             "      - { fourcc: MJPG, sizes: [320x240] }\n"
             "      - { fourcc: YUYV, sizes: [320x240] }\n");
    format = negotiate(settings(PixelFormatChoice::Auto));
    EXPECT_EQ(format.fourcc, V4L2_PIX_FMT_YUYV);
    EXPECT_EQ(format.bytes_per_line, static_cast<uint32_t>(2 * kWidth));
    EXPECT_NE(format.reason.find("GREY not at 320x240"), std::string::npos) << format.reason;

    loadFake("      - { fourcc: MJPG, sizes: [320x240] }\n");
    format = negotiate(settings(PixelFormatChoice::Auto));
    EXPECT_EQ(format.fourcc, V4L2_PIX_FMT_MJPEG);
    EXPECT_NE(format.reason.find("GREY not offered; YUYV not offered"), std::string::npos)
        << format.reason;
    EXPECT_EQ(format.width, kWidth);
    EXPECT_EQ(format.height, kHeight);
}

TEST_F(V4l2DeviceTest, RefusalNamesWhatTheDeviceOffers)
{
    loadFake("      - { fourcc: YUYV, sizes: [320x240, 640x480@15] }\n"
             "      - { fourcc: MJPG, sizes: [320x240, 1280x720@10] }\n");
    CameraSettings s = settings(PixelFormatChoice::Auto);
    s.width = 1920;
    s.height = 1080;
    negotiate(s, -EINVAL);
    EXPECT_NE(error_.find("cannot deliver GREY, YUYV, MJPG, RGB3 or BGR3 1920x1080 @ 100 fps"),
              std::string::npos)
        << error_;
    EXPECT_NE(error_.find("YUYV 320x240 @ 100/30 fps, 640x480 @ 15 fps"), std::string::npos)
        << error_;
    EXPECT_NE(error_.find("MJPG 320x240 @ 100/30 fps, 1280x720 @ 10 fps"), std::string::npos)
        << error_;

    // A format the device lacks, asked for by name.
    negotiate(settings(PixelFormatChoice::Grey), -EINVAL);
    EXPECT_NE(error_.find("cannot deliver GREY 320x240"), std::string::npos) << error_;
    EXPECT_NE(error_.find("YUYV 320x240"), std::string::npos) << error_;

    // The right size at a rate it does not offer there.
    s = settings(PixelFormatChoice::Yuyv, 30.0);
    s.width = 640;
    s.height = 480;
    negotiate(s, -EINVAL);
    EXPECT_NE(error_.find("640x480 @ 15 fps"), std::string::npos) << error_;
}

TEST_F(V4l2DeviceTest, FrameRateIsSetAndReported)
{
    loadFake("      - { fourcc: YUYV, sizes: [320x240] }\n");
    NegotiatedFormat format = negotiate(settings(PixelFormatChoice::Yuyv, 30.0));
    EXPECT_DOUBLE_EQ(format.fps, 30.0);
    EXPECT_NE(format.reason.find("YUYV as configured"), std::string::npos) << format.reason;
    format = negotiate(settings(PixelFormatChoice::Yuyv, 100.0));
    EXPECT_DOUBLE_EQ(format.fps, 100.0);
}

TEST_F(V4l2DeviceTest, ControlsAreAppliedAndReadBack)
{
    loadFake("      - { fourcc: YUYV, sizes: [320x240] }\n",
             "    controls:\n"
             "      - { name: exposure_auto, default: 3 }\n"
             "      - { name: exposure_absolute, min: 3, max: 2047, step: 1, default: 250 }\n"
             "      - { name: gain, min: 0, max: 100, step: 4, default: 32 }\n"
             "      - { name: power_line_frequency, default: 1 }\n");
    V4l2Device device;
    ASSERT_EQ(device.open(kFakeLeft), 0) << device.errorText();

    CameraControls controls;
    controls.auto_exposure = false;
    controls.exposure_us = 10'000;   // 100 device units of 100 us
    controls.gain = 50;              // not on the step grid: 48
    controls.white_balance_k = 4500; // the device has no white balance
    controls.power_line = PowerLineFrequency::Hz60;
    const std::vector<ControlReading> readings = device.applyControls(controls, false);

    const ControlReading* exposure_auto = findControl(readings, "auto_exposure");
    ASSERT_NE(exposure_auto, nullptr);
    EXPECT_EQ(exposure_auto->actual_value, V4L2_EXPOSURE_MANUAL);
    EXPECT_TRUE(exposure_auto->error.empty()) << exposure_auto->error;

    const ControlReading* exposure = findControl(readings, "exposure_us");
    ASSERT_NE(exposure, nullptr);
    EXPECT_EQ(exposure->actual_value, 10'000);
    EXPECT_TRUE(exposure->error.empty()) << exposure->error;

    const ControlReading* gain = findControl(readings, "gain");
    ASSERT_NE(gain, nullptr);
    EXPECT_EQ(gain->requested_value, 50);
    EXPECT_EQ(gain->actual_value, 48);
    EXPECT_NE(gain->error.find("set 48"), std::string::npos) << gain->error;

    const ControlReading* white_balance = findControl(readings, "white_balance_k");
    ASSERT_NE(white_balance, nullptr);
    EXPECT_FALSE(white_balance->present);
    EXPECT_EQ(white_balance->error, "not offered by the device");

    const ControlReading* power_line = findControl(readings, "power_line_frequency");
    ASSERT_NE(power_line, nullptr);
    // The fake's menu stops at 2 (60 Hz), as UVC cameras' does.
    EXPECT_EQ(power_line->actual_value, 2);

    // An independent read gives the same values.
    const std::vector<ControlReading> again = device.readControls();
    EXPECT_EQ(findControl(again, "exposure_us")->actual_value, 10'000);
    EXPECT_EQ(findControl(again, "gain")->actual_value, 48);
}

TEST_F(V4l2DeviceTest, LockExposureFreezesTheCurrentExposure)
{
    loadFake("      - { fourcc: YUYV, sizes: [320x240] }\n",
             "    controls:\n"
             "      - { name: exposure_auto, default: 3 }\n"
             "      - { name: exposure_absolute, min: 3, max: 2047, step: 1, default: 250 }\n");
    V4l2Device device;
    ASSERT_EQ(device.open(kFakeLeft), 0) << device.errorText();
    CameraControls controls;
    controls.auto_exposure = true; // lock_exposure wins over it
    const std::vector<ControlReading> readings = device.applyControls(controls, true);
    EXPECT_EQ(findControl(readings, "auto_exposure")->actual_value, V4L2_EXPOSURE_MANUAL);
    EXPECT_EQ(findControl(readings, "exposure_us")->actual_value, 25'000);
    EXPECT_TRUE(findControl(readings, "exposure_us")->error.empty());
}

TEST_F(V4l2DeviceTest, ListingShowsFormatsRatesAndById)
{
    loadFake("      - { fourcc: GREY, sizes: [320x240, 640x480@15] }\n"
             "      - { fourcc: MJPG, sizes: [1280x720@10] }\n",
             "",
             "  - path: /dev/video-fake-right\n"
             "    card: Fake Stereo Right\n"
             "    images: " +
                 (dir_ / "scene.png").string() +
                 "\n"
                 "    fps: [30]\n"
                 "    formats:\n"
                 "      - { fourcc: YUYV, sizes: [320x240] }\n");
    const DeviceList list = listCaptureDevices();
    const auto left = std::find_if(list.devices.begin(), list.devices.end(),
                                   [](const DeviceInfo& d) { return d.path == kFakeLeft; });
    ASSERT_NE(left, list.devices.end()) << formatDeviceList(list);
    EXPECT_EQ(left->identity.card, "Fake Stereo Left");
    ASSERT_EQ(left->by_id_paths.size(), 1u);
    EXPECT_EQ(left->by_id_paths[0], std::string("/dev/v4l/by-id/") + test::kFakeLeftById);
    ASSERT_EQ(left->formats.size(), 2u);
    EXPECT_EQ(left->formats[0].name, "GREY");
    ASSERT_EQ(left->formats[0].sizes.size(), 2u);
    EXPECT_EQ(left->formats[0].sizes[1].width, 640);
    EXPECT_EQ(left->formats[0].sizes[1].fps, std::vector<double>{15.0});
    const auto right = std::find_if(list.devices.begin(), list.devices.end(),
                                    [](const DeviceInfo& d) { return d.path == test::kFakeRight; });
    ASSERT_NE(right, list.devices.end());
    EXPECT_TRUE(right->by_id_paths.empty());

    const std::string text = formatDeviceList(list);
    EXPECT_NE(text.find("/dev/video-fake-left: Fake Stereo Left (driver uvcvideo"),
              std::string::npos)
        << text;
    EXPECT_NE(text.find("GREY 320x240 @ 100/30 fps, 640x480 @ 15 fps"), std::string::npos) << text;
    EXPECT_NE(text.find("by-id: /dev/v4l/by-id/usb-Fake_Stereo_Left"), std::string::npos) << text;

    const nlohmann::json json = nlohmann::json::parse(deviceListJson(list));
    bool found = false;
    for (const nlohmann::json& device : json.at("devices")) {
        if (device.at("path") != kFakeLeft)
            continue;
        found = true;
        EXPECT_EQ(device.at("card"), "Fake Stereo Left");
        EXPECT_EQ(device.at("formats").at(1).at("fourcc"), "MJPG");
        EXPECT_EQ(device.at("formats").at(1).at("sizes").at(0).at("width"), 1280);
        EXPECT_EQ(device.at("formats").at(1).at("sizes").at(0).at("fps").at(0), 10.0);
    }
    EXPECT_TRUE(found);
}

} // namespace
} // namespace stereod
