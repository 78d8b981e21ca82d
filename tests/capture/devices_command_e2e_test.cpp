// `stereoctl devices` and `stereod --list-devices` as users run them, with the fake V4L2
// device preloaded into the unchanged binaries: each camera with its formats, sizes,
// rates and by-id path, as text and as JSON; exit 1 when there is no camera.

#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "capture/device_list.hpp"
#include "tests/support/fake_cameras.hpp"
#include "tests/support/process.hpp"

namespace stereod {
namespace {

class DevicesCommandTest : public test::FakeCameraTest {
  protected:
    // Writes the description for the child processes (this process loads it too, which
    // the fixture's TearDown unloads).
    std::vector<std::string> fakeEnvironment()
    {
        loadFake("      - { fourcc: YUYV, sizes: [320x240, 640x480@15] }\n"
                 "      - { fourcc: MJPG, sizes: [1280x720@30] }\n");
        return fake_v4l2::childEnvironment(STEREOD_FAKE_V4L2_LIBRARY,
                                           (dir_ / "devices.yaml").string());
    }
};

TEST_F(DevicesCommandTest, StereoctlListsTheCameraAsText)
{
    const test::ProcessResult result =
        test::runProcess({test::stereoctlPath(), "devices"}, fakeEnvironment());
    EXPECT_EQ(result.exit_code, 0) << result.err;
    EXPECT_NE(result.out.find("/dev/video-fake-left: Fake Stereo Left (driver uvcvideo"),
              std::string::npos)
        << result.out;
    EXPECT_NE(result.out.find(std::string("by-id: /dev/v4l/by-id/") + test::kFakeLeftById),
              std::string::npos)
        << result.out;
    EXPECT_NE(result.out.find("YUYV 320x240 @ 100/30 fps, 640x480 @ 15 fps"), std::string::npos)
        << result.out;
    EXPECT_NE(result.out.find("MJPG 1280x720 @ 30 fps"), std::string::npos) << result.out;
}

TEST_F(DevicesCommandTest, StereoctlListsTheCameraAsJson)
{
    const test::ProcessResult result =
        test::runProcess({test::stereoctlPath(), "devices", "--json"}, fakeEnvironment());
    ASSERT_EQ(result.exit_code, 0) << result.err;
    const nlohmann::json json = nlohmann::json::parse(result.out);
    const nlohmann::json* left = nullptr;
    for (const nlohmann::json& device : json.at("devices")) {
        if (device.at("path") == test::kFakeLeft)
            left = &device;
    }
    ASSERT_NE(left, nullptr) << result.out;
    EXPECT_EQ(left->at("by_id").at(0), std::string("/dev/v4l/by-id/") + test::kFakeLeftById);
    EXPECT_EQ(left->at("formats").at(0).at("fourcc"), "YUYV");
    EXPECT_EQ(left->at("formats").at(0).at("sizes").at(1).at("height"), 480);
    EXPECT_EQ(left->at("formats").at(0).at("sizes").at(1).at("fps").at(0), 15.0);
}

TEST_F(DevicesCommandTest, StereodListDevicesPrintsTheSameList)
{
    const std::vector<std::string> env = fakeEnvironment();
    const test::ProcessResult daemon =
        test::runProcess({test::stereodPath(), "--list-devices"}, env);
    const test::ProcessResult ctl = test::runProcess({test::stereoctlPath(), "devices"}, env);
    EXPECT_EQ(daemon.exit_code, 0) << daemon.err;
    EXPECT_EQ(daemon.out, ctl.out);
}

TEST_F(DevicesCommandTest, NoCameraExitsWithOne)
{
    if (!listCaptureDevices().devices.empty())
        GTEST_SKIP() << "this machine has V4L2 cameras";
    // An empty description: the fake is preloaded but offers no device.
    const std::filesystem::path empty = dir_ / "none.yaml";
    std::ofstream(empty) << "devices: []\n";
    const std::vector<std::string> env =
        fake_v4l2::childEnvironment(STEREOD_FAKE_V4L2_LIBRARY, empty.string());
    const test::ProcessResult result = test::runProcess({test::stereoctlPath(), "devices"}, env);
    EXPECT_EQ(result.exit_code, 1) << result.err;
    EXPECT_EQ(result.out, "no V4L2 capture devices found\n");
}

} // namespace
} // namespace stereod
