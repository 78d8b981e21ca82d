// The `status` object built from plain values: its members in the documented order, the
// numbers rounded for people, and the optional members present only when they apply.

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "protocol/status_reply.hpp"
#include "tests/protocol/sample_reading.hpp"

namespace stereod {
namespace {

ServiceStatus runningStatus()
{
    ServiceStatus status;
    status.uptime_s = 12.345;
    status.state = "running";
    status.source.kind = "v4l2";
    status.source.state = "running";
    status.source.cameras.push_back(
        {"/dev/video0", "running", 29.987, 360, 2, 1, "short frame", 3, ""});
    status.source.pairs = 357;
    status.source.ring_dropped = 4;
    status.source.skew_mean_ms = 0.12345;
    status.source.warnings = {"exposure differs"};
    status.pipeline.frames = 350;
    status.pipeline.fps = 29.456;
    status.pipeline.matcher = "census-sgm";
    status.pipeline.range.num_disparities = 128;
    status.pipeline.range.closest_depth_m = 0.45678;
    status.pipeline.stage_mean_ms.match_ms = 12.34567;
    status.pipeline.publish_mean_ms = 0.5;
    status.pipeline.latency_p99_ms = 40.0004;
    status.calibration_health.state = "ok";
    StatusHealthChecks& checks = status.calibration_health.checks.emplace();
    checks.row_offset_px = 0.12345;
    checks.offset_px = -0.23456;
    checks.roll_deg = 0.312345;
    checks.max_row_error_px = 1.23456;
    checks.last_check = "degraded";
    checks.state_changes = 2;
    checks.matches = 210;
    checks.checks = 6;
    checks.interval_s = 2.0;
    checks.checked_age_s = 1.2345;
    status.calibration.path = "/etc/stereod/calibration.yaml";
    status.calibration.kind = "full";
    RectifiedGeometry geometry;
    geometry.focal_px = 700.5;
    geometry.baseline_m = 0.12;
    geometry.image_size = ImageSize{640, 480};
    status.calibration.geometry = geometry;
    status.calibration.rms_px = 0.31;
    status.clients.connected = 2;
    status.clients.accepted = 9;
    status.reading.reading = sampleValidReading();
    status.now_ns = status.reading.reading.stamp_ns + 5'000'000;
    return status;
}

std::vector<std::string> keys(const Json& object)
{
    std::vector<std::string> out;
    for (const auto& [key, value] : object.items())
        out.push_back(key);
    return out;
}

TEST(StatusReply, MembersInTheDocumentedOrder)
{
    const Json status = statusToJson(runningStatus());
    EXPECT_EQ(keys(status),
              (std::vector<std::string>{"uptime_s", "state", "source", "pipeline",
                                        "calibration_health", "calibration", "clients", "live_view",
                                        "ros2", "reading", "max_reading_age_ms"}));
    EXPECT_EQ(status["state"], "running");
    EXPECT_EQ(
        keys(status["clients"]),
        (std::vector<std::string>{"connected", "subscribers", "frames_dropped", "disconnected_slow",
                                  "accepted", "rejected", "not_allowed", "idle_closed"}));
    EXPECT_EQ(status["clients"]["connected"], 2);
    EXPECT_EQ(status["clients"]["accepted"], 9);
    EXPECT_EQ(status["reading"]["valid"], true);
    EXPECT_DOUBLE_EQ(status["reading"]["age_ms"].get<double>(), 5.0);
}

TEST(StatusReply, NumbersAreRoundedForPeople)
{
    const Json status = statusToJson(runningStatus());
    EXPECT_DOUBLE_EQ(status["uptime_s"].get<double>(), 12.3);
    const Json& camera = status["source"]["cameras"][0];
    EXPECT_EQ(camera["name"], "/dev/video0");
    EXPECT_DOUBLE_EQ(camera["fps"].get<double>(), 29.99);
    EXPECT_EQ(camera["last_bad_frame"], "short frame");
    EXPECT_EQ(camera["unpaired"], 3);
    EXPECT_DOUBLE_EQ(status["source"]["skew_ms"]["mean"].get<double>(), 0.123);
    EXPECT_EQ(status["source"]["ring_dropped"], 4);
    EXPECT_EQ(status["source"]["warnings"], Json::array({"exposure differs"}));
    const Json& pipeline = status["pipeline"];
    EXPECT_DOUBLE_EQ(pipeline["fps"].get<double>(), 29.46);
    EXPECT_EQ(pipeline["matcher"], "census-sgm");
    EXPECT_EQ(pipeline["num_disparities"], 128);
    EXPECT_DOUBLE_EQ(pipeline["closest_depth_m"].get<double>(), 0.457);
    EXPECT_DOUBLE_EQ(pipeline["stage_ms"]["match"].get<double>(), 12.346);
    EXPECT_DOUBLE_EQ(pipeline["stage_ms"]["publish"].get<double>(), 0.5);
    EXPECT_DOUBLE_EQ(pipeline["latency_ms"]["p99"].get<double>(), 40.0);
    const Json& health = status["calibration_health"];
    EXPECT_DOUBLE_EQ(health["row_offset_px"].get<double>(), 0.123);
    EXPECT_DOUBLE_EQ(health["offset_px"].get<double>(), -0.235);
    EXPECT_DOUBLE_EQ(health["roll_deg"].get<double>(), 0.3123);
    EXPECT_DOUBLE_EQ(health["max_row_error_px"].get<double>(), 1.235);
    EXPECT_EQ(health["last_check"], "degraded");
    EXPECT_EQ(health["state_changes"], 2);
    EXPECT_EQ(health["matches"], 210);
    EXPECT_DOUBLE_EQ(health["checked_age_s"].get<double>(), 1.23);
    const Json& calibration = status["calibration"];
    EXPECT_EQ(calibration["kind"], "full");
    EXPECT_DOUBLE_EQ(calibration["focal_px"].get<double>(), 700.5);
    EXPECT_EQ(calibration["width"], 640);
    EXPECT_DOUBLE_EQ(calibration["rms_px"].get<double>(), 0.31);
    EXPECT_FALSE(calibration.contains("epipolar_error_px"));
}

TEST(StatusReply, OptionalMembersOnlyWhenTheyApply)
{
    ServiceStatus status = runningStatus();
    EXPECT_FALSE(statusToJson(status)["source"].contains("down_reason"));
    EXPECT_FALSE(statusToJson(status)["calibration_health"].contains("reason"));
    status.source.down_reason = "the v4l2 source is failed: ENODEV";
    status.calibration_health.checks->checked_age_s.reset();
    const Json json = statusToJson(status);
    EXPECT_EQ(json["source"]["down_reason"], "the v4l2 source is failed: ENODEV");
    EXPECT_FALSE(json["calibration_health"].contains("checked_age_s"));
}

TEST(StatusReply, UncalibratedSaysSoAndNoMore)
{
    ServiceStatus status;
    status.state = "uncalibrated";
    status.calibration_health.state = "unknown";
    status.calibration_health.reason = "uncalibrated";
    status.reading.has_frame = false;
    status.reading.reading.reason = NoReadingReason::Uncalibrated;
    const Json json = statusToJson(status);
    EXPECT_EQ(json["calibration_health"],
              Json::parse(R"({"state":"unknown","reason":"uncalibrated"})"));
    EXPECT_EQ(json["calibration"], Json::parse(R"({"path":"","kind":"none"})"));
    EXPECT_EQ(json["reading"]["reason"]["code"], "uncalibrated");
}

} // namespace
} // namespace stereod
