#include "protocol/status_reply.hpp"

#include <utility>

#include "protocol/json_writer.hpp"

namespace stereod {

namespace {

Json sourceJson(const StatusSource& source)
{
    Json out = Json::object();
    out["kind"] = source.kind;
    out["state"] = source.state;
    out["last_error"] = source.last_error;
    if (source.down_reason)
        out["down_reason"] = *source.down_reason;
    Json cameras = Json::array();
    for (const StatusCamera& camera : source.cameras) {
        cameras.push_back({{"name", camera.name},
                           {"state", camera.state},
                           {"fps", roundTo(camera.fps, 2)},
                           {"frames", camera.frames},
                           {"dropped", camera.dropped},
                           {"bad_frames", camera.bad_frames},
                           {"last_bad_frame", camera.last_bad_frame},
                           {"unpaired", camera.unpaired},
                           {"last_error", camera.last_error}});
    }
    out["cameras"] = std::move(cameras);
    out["pairs"] = source.pairs;
    out["ring_dropped"] = source.ring_dropped;
    out["unpaired_dropped"] = source.unpaired_dropped;
    out["skew_ms"] = {{"mean", roundTo(source.skew_mean_ms, 3)},
                      {"p99", roundTo(source.skew_p99_ms, 3)},
                      {"max", roundTo(source.skew_max_ms, 3)}};
    out["clock_offset"] = {{"detected", source.clock_offset_detected},
                           {"estimate_ms", roundTo(source.clock_offset_ms, 3)}};
    out["warnings"] = source.warnings;
    return out;
}

Json pipelineJson(const StatusPipeline& pipeline)
{
    Json out = Json::object();
    out["frames"] = pipeline.frames;
    out["fps"] = roundTo(pipeline.fps, 2);
    out["matcher"] = pipeline.matcher;
    out["num_disparities"] = pipeline.range.num_disparities;
    out["min_disparity"] = pipeline.range.min_disparity;
    out["closest_depth_m"] = roundTo(pipeline.range.closest_depth_m, 3);
    out["extended_range"] = pipeline.range.extended;
    out["full_resolution_closest_depth_m"] = roundTo(pipeline.range.range_closest_depth_m, 3);
    out["disparity_range_capped"] = pipeline.range.capped;
    if (pipeline.max_output_depth_m)
        out["max_output_depth_m"] = roundTo(*pipeline.max_output_depth_m, 3);
    out["region"] = {{"x", pipeline.region.x},
                     {"y", pipeline.region.y},
                     {"width", pipeline.region.width},
                     {"height", pipeline.region.height}};
    out["bad_frames"] = pipeline.bad_frames;
    out["out_of_sync"] = pipeline.out_of_sync;
    const StageTimings& stage = pipeline.stage_mean_ms;
    out["stage_ms"] = {{"rectify", roundTo(stage.rectify_ms, 3)},
                       {"match", roundTo(stage.match_ms, 3)},
                       {"depth", roundTo(stage.depth_ms, 3)},
                       {"nearest", roundTo(stage.nearest_ms, 3)},
                       {"cloud", roundTo(stage.cloud_ms, 3)},
                       {"zones", roundTo(pipeline.zones_mean_ms, 3)},
                       {"publish", roundTo(pipeline.publish_mean_ms, 3)}};
    // Parts of stage_ms.match (not stages of their own: the stage table adds stage_ms up).
    out["match_parts_ms"] = {{"extended_range", roundTo(stage.extended_range_ms, 3)},
                             {"near_field_probe", roundTo(stage.near_field_probe_ms, 3)}};
    out["latency_ms"] = {{"p50", roundTo(pipeline.latency_p50_ms, 3)},
                         {"p99", roundTo(pipeline.latency_p99_ms, 3)}};
    return out;
}

Json calibrationHealthJson(const StatusCalibrationHealth& health)
{
    Json out = Json::object();
    out["state"] = health.state;
    if (!health.reason.empty())
        out["reason"] = health.reason;
    if (!health.checks)
        return out;
    const StatusHealthChecks& checks = *health.checks;
    out["row_offset_px"] = roundTo(checks.row_offset_px, 3);
    out["row_offset_p90_px"] = roundTo(checks.row_offset_p90_px, 3);
    out["offset_px"] = roundTo(checks.offset_px, 3);
    out["roll_deg"] = roundTo(checks.roll_deg, 4);
    out["max_row_error_px"] = roundTo(checks.max_row_error_px, 3);
    out["last_check"] = checks.last_check;
    out["state_changes"] = checks.state_changes;
    out["matches"] = checks.matches;
    out["trend_px_per_min"] = roundTo(checks.trend_px_per_min, 4);
    out["checks"] = checks.checks;
    out["check_ms"] = roundTo(checks.check_ms, 2);
    out["interval_s"] = checks.interval_s;
    if (checks.checked_age_s)
        out["checked_age_s"] = roundTo(*checks.checked_age_s, 2);
    return out;
}

Json calibrationJson(const StatusCalibration& calibration)
{
    Json out = Json::object();
    out["path"] = calibration.path;
    out["kind"] = calibration.kind;
    if (!calibration.geometry)
        return out;
    const RectifiedGeometry& geometry = *calibration.geometry;
    out["focal_px"] = geometry.focal_px;
    out["baseline_m"] = geometry.baseline_m;
    out["doffs_px"] = geometry.doffs_px;
    out["cx_px"] = geometry.cx_px;
    out["cy_px"] = geometry.cy_px;
    out["width"] = geometry.image_size.width;
    out["height"] = geometry.image_size.height;
    if (calibration.rms_px)
        out["rms_px"] = *calibration.rms_px;
    if (calibration.epipolar_error_px)
        out["epipolar_error_px"] = *calibration.epipolar_error_px;
    return out;
}

Json clientsJson(const ClientCounters& clients)
{
    return {{"connected", clients.connected},
            {"subscribers", clients.subscribers},
            {"frames_dropped", clients.frames_dropped},
            {"disconnected_slow", clients.disconnected_slow},
            {"accepted", clients.accepted},
            {"rejected", clients.rejected},
            {"not_allowed", clients.not_allowed},
            {"idle_closed", clients.idle_closed}};
}

} // namespace

Json statusToJson(const ServiceStatus& status)
{
    Json out = Json::object();
    out["uptime_s"] = roundTo(status.uptime_s, 1);
    out["state"] = status.state;
    out["source"] = sourceJson(status.source);
    out["pipeline"] = pipelineJson(status.pipeline);
    out["calibration_health"] = calibrationHealthJson(status.calibration_health);
    out["calibration"] = calibrationJson(status.calibration);
    out["clients"] = clientsJson(status.clients);
    const StatusLiveView& live = status.live_view;
    out["live_view"] = {{"listen", live.listen},
                        {"listening", live.listening},
                        {"error", live.error},
                        {"clients", live.clients},
                        {"messages_sent", live.messages_sent},
                        {"bytes_sent", live.bytes_sent},
                        {"readings_sent", live.readings_sent},
                        {"frames_dropped", live.frames_dropped},
                        {"clients_dropped", live.clients_dropped},
                        {"refused", live.refused}};
    const StatusRos2& ros2 = status.ros2;
    out["ros2"] = {{"enabled", ros2.enabled},
                   {"publishing", ros2.publishing},
                   {"error", ros2.error},
                   {"namespace", ros2.ns},
                   {"domain_id", ros2.domain_id},
                   {"localhost_only", ros2.localhost_only},
                   {"readers", ros2.readers},
                   {"frames", ros2.frames},
                   {"frames_skipped", ros2.frames_skipped},
                   {"messages", ros2.messages},
                   {"write_errors", ros2.write_errors}};
    out["reading"] = readingToJson(status.reading, status.now_ns);
    out["max_reading_age_ms"] = status.max_reading_age_ms;
    return out;
}

} // namespace stereod
