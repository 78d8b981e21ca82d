// The camera keys of the configuration (source.type v4l2 / side_by_side, source.cameras):
// reading, validation with file:line, and their place in diffConfig.

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "config/service_config.hpp"

namespace stereod {
namespace {

// The problems of a text that must be refused.
std::vector<std::string> problemsOf(const std::string& yaml)
{
    try {
        parseConfig(yaml, "rig.yaml");
    } catch (const ConfigError& e) {
        return e.problems();
    }
    ADD_FAILURE() << "accepted:\n" << yaml;
    return {};
}

bool has(const std::vector<std::string>& problems, const std::string& text)
{
    for (const auto& problem : problems) {
        if (problem.find(text) != std::string::npos)
            return true;
    }
    return false;
}

std::string joined(const std::vector<std::string>& problems)
{
    std::string out;
    for (const auto& problem : problems)
        out += problem + "\n";
    return out;
}

TEST(CamerasConfig, TwoCameraRigIsRead)
{
    const ServiceConfig config = parseConfig(R"(source:
  type: v4l2
  max_skew_ms: 8
  cameras:
    left: /dev/v4l/by-id/usb-Left-video-index0
    right: /dev/v4l/by-id/usb-Right-video-index0
    format: mjpeg
    width: 1280
    height: 720
    fps: 30
    lock_exposure: true
    controls:
      exposure_us: 8000
      gain: 16
      auto_white_balance: false
      white_balance_k: 4600
      power_line_frequency: 50hz
)",
                                             "rig.yaml");
    const CamerasConfig& cameras = config.source.cameras;
    EXPECT_EQ(config.source.kind, SourceKind::V4l2);
    EXPECT_EQ(cameras.left, "/dev/v4l/by-id/usb-Left-video-index0");
    EXPECT_EQ(cameras.right, "/dev/v4l/by-id/usb-Right-video-index0");
    EXPECT_EQ(cameras.format, PixelFormatChoice::Mjpeg);
    EXPECT_EQ(cameras.width, 1280);
    EXPECT_EQ(cameras.height, 720);
    EXPECT_TRUE(cameras.lock_exposure);
    EXPECT_FALSE(cameras.controls.auto_exposure.has_value());
    EXPECT_EQ(cameras.controls.exposure_us, 8000);
    EXPECT_EQ(cameras.controls.gain, 16);
    EXPECT_EQ(cameras.controls.auto_white_balance, false);
    EXPECT_EQ(cameras.controls.white_balance_k, 4600);
    EXPECT_EQ(cameras.controls.power_line, PowerLineFrequency::Hz50);

    // Every camera key needs a restart, and `keep` is the default of a control.
    const ConfigChange change = diffConfig(defaultConfig(), config);
    EXPECT_EQ(change.changed, change.restart_needed);
    EXPECT_NE(
        std::find(change.changed.begin(), change.changed.end(), "source.cameras.controls.gain"),
        change.changed.end());
    const ServiceConfig kept =
        parseConfig("source:\n  cameras:\n    controls:\n      gain: keep\n", "k.yaml");
    EXPECT_FALSE(kept.source.cameras.controls.gain.has_value());
    EXPECT_TRUE(diffConfig(defaultConfig(), kept).changed.empty());
}

TEST(CamerasConfig, SideBySideDeviceIsRead)
{
    const ServiceConfig config = parseConfig(
        "source:\n  type: side_by_side\n  cameras:\n    device: /dev/video4\n    width: 2560\n"
        "    height: 720\n    format: yuyv\n",
        "sbs.yaml");
    EXPECT_EQ(config.source.kind, SourceKind::SideBySide);
    EXPECT_EQ(config.source.cameras.device, "/dev/video4");
    EXPECT_EQ(config.source.cameras.format, PixelFormatChoice::Yuyv);
}

TEST(CamerasConfig, MissingDevicesAreNamedWithTheirLines)
{
    const auto problems = problemsOf("source:\n  type: v4l2\n");
    EXPECT_TRUE(has(problems, "rig.yaml: source.cameras.left: empty with source.type v4l2"))
        << joined(problems);
    EXPECT_TRUE(has(problems, "source.cameras.right: empty with source.type v4l2"))
        << joined(problems);

    const auto same = problemsOf(
        "source:\n  type: v4l2\n  cameras:\n    left: /dev/video0\n    right: /dev/video0\n");
    EXPECT_TRUE(has(same, "rig.yaml:5: source.cameras.right: the same device as "
                          "source.cameras.left"))
        << joined(same);

    const auto sbs = problemsOf("source:\n  type: side_by_side\n  cameras:\n    width: 641\n");
    EXPECT_TRUE(has(sbs, "source.cameras.device: empty with source.type side_by_side"))
        << joined(sbs);
    EXPECT_TRUE(has(sbs, "rig.yaml:4: source.cameras.width: odd with source.type side_by_side"))
        << joined(sbs);
}

TEST(CamerasConfig, BadValuesAreRefusedWithWhatIsExpected)
{
    const auto problems = problemsOf(R"(source:
  cameras:
    format: rgb
    width: 0
    fps: -5
    controls:
      exposure_us: long
      gain: -1
      white_balance_k: 99999
      power_line_frequency: 55hz
      auto_exposure: maybe
)");
    EXPECT_TRUE(has(problems, "rig.yaml:3: source.cameras.format: unknown value (got rgb, "
                              "expected auto, grey, yuyv, mjpeg, rgb24 or bgr24"))
        << joined(problems);
    EXPECT_TRUE(has(problems, "rig.yaml:4: source.cameras.width: out of range (got 0"))
        << joined(problems);
    EXPECT_TRUE(has(problems, "rig.yaml:5: source.cameras.fps: out of range (got -5"))
        << joined(problems);
    EXPECT_TRUE(has(problems, "rig.yaml:7: source.cameras.controls.exposure_us: not keep or an "
                              "integer (got long, expected keep, or an integer in us)"))
        << joined(problems);
    EXPECT_TRUE(has(problems, "rig.yaml:8: source.cameras.controls.gain: out of range (got -1"))
        << joined(problems);
    EXPECT_TRUE(has(problems,
                    "rig.yaml:9: source.cameras.controls.white_balance_k: out of range (got 99999"))
        << joined(problems);
    EXPECT_TRUE(has(problems, "rig.yaml:10: source.cameras.controls.power_line_frequency: unknown "
                              "value (got 55hz, expected keep, disabled, 50hz, 60hz or auto)"))
        << joined(problems);
    EXPECT_TRUE(has(problems, "rig.yaml:11: source.cameras.controls.auto_exposure: not keep, "
                              "true or false"))
        << joined(problems);
    EXPECT_EQ(problems.size(), 8u) << joined(problems);
}

TEST(CamerasConfig, MaxSkewMustStayBelowHalfTheFramePeriod)
{
    // At 60 fps a partner 9 ms away may be the next frame's.
    const auto problems = problemsOf(R"(source:
  type: v4l2
  max_skew_ms: 9
  cameras:
    left: /dev/video0
    right: /dev/video2
    fps: 60
)");
    EXPECT_TRUE(has(problems, "rig.yaml:3: source.max_skew_ms: not below half the frame period "
                              "(got 9, expected < 8.333333333333334 ms at source.cameras.fps 60)"))
        << joined(problems);
    EXPECT_NO_THROW(
        parseConfig("source:\n  type: v4l2\n  max_skew_ms: 8\n  cameras:\n    left: /dev/video0\n"
                    "    right: /dev/video2\n    fps: 60\n",
                    "ok.yaml"));
}

TEST(CamerasConfig, LockedExposureContradictsAutoExposure)
{
    const auto problems = problemsOf(
        "source:\n  cameras:\n    lock_exposure: true\n    controls:\n      auto_exposure: true\n");
    EXPECT_TRUE(has(problems, "rig.yaml:3: source.cameras.lock_exposure: contradicts "
                              "source.cameras.controls.auto_exposure: true"))
        << joined(problems);
}

TEST(CamerasConfig, ReplayOnTheCommandLineReplacesTheCameras)
{
    ServiceConfig config = parseConfig(
        "source:\n  type: v4l2\n  cameras:\n    left: /dev/video0\n    right: /dev/video2\n",
        "rig.yaml");
    ConfigOverrides overrides;
    overrides.replay_path = STEREOD_SOURCE_DIR;
    applyOverrides(config, overrides);
    EXPECT_EQ(config.source.kind, SourceKind::Replay);
    EXPECT_NO_THROW(validateConfig(config));
}

} // namespace
} // namespace stereod
