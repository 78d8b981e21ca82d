#include "protocol/reading_json.hpp"

#include <algorithm>
#include <array>
#include <cstdio>

#include "base/clock.hpp"
#include "protocol/json_writer.hpp"

namespace stereod {

namespace {

// Writes the reason sentence into `buffer` without allocating, with the detail after a
// colon; returns its length.
std::size_t formatReasonMessage(const Reading& reading, std::string_view detail, char* buffer,
                                std::size_t size)
{
    int written = 0;
    switch (reading.reason) {
    case NoReadingReason::None:
        written = 0;
        break;
    case NoReadingReason::OutOfSync:
        written = std::snprintf(buffer, size, "%s: %.1f ms apart, %.1f ms allowed",
                                reasonText(reading.reason), reading.skew_ms, reading.max_skew_ms);
        break;
    case NoReadingReason::Stale:
        written = std::snprintf(buffer, size, "%s: %.1f ms old, %.1f ms allowed",
                                reasonText(reading.reason), reading.age_ms, reading.max_age_ms);
        break;
    case NoReadingReason::Uncalibrated:
        written = std::snprintf(buffer, size,
                                "uncalibrated: the service runs without a calibration (raw frames "
                                "only); calibrate with `stereoctl calibrate` and restart with it");
        break;
    case NoReadingReason::TooFewValidPixels:
        written = std::snprintf(buffer, size, "%s: %.1f %% valid, %.1f %% needed",
                                reasonText(reading.reason), 100.0 * reading.valid_fraction,
                                100.0 * reading.min_valid_fraction);
        break;
    case NoReadingReason::NothingInRange:
        written = std::snprintf(
            buffer, size, "%s: %.0f pixels in range, %u needed (%.1f %% valid, %.1f %% in range)",
            reasonText(reading.reason), reading.in_range_fraction * reading.region_pixels,
            reading.min_pixels, 100.0 * reading.valid_fraction, 100.0 * reading.in_range_fraction);
        break;
    case NoReadingReason::CalibrationSuspect:
        written = std::snprintf(buffer, size,
                                "%s: rows of matching points %+.2f px apart; recalibrate, or "
                                "`stereoctl check-calibration --fix`",
                                reasonText(reading.reason), reading.calibration_row_offset_px);
        break;
    case NoReadingReason::NearerThanRange:
        written =
            std::snprintf(buffer, size,
                          "%s: nearer than %.3f m (%.1f %% of the region is near-field "
                          "evidence); raise matcher.num_disparities or lower matcher.min_depth_m "
                          "to measure it",
                          reasonText(reading.reason), reading.nearer_than_m,
                          100.0 * reading.range_limit_fraction);
        break;
    default:
        written = std::snprintf(buffer, size, "%s", reasonText(reading.reason));
        break;
    }
    if (written < 0 || size == 0)
        return 0;
    std::size_t length = std::min(static_cast<std::size_t>(written), size - 1);
    if (!detail.empty() && length > 0 && length + 3 < size) {
        const int more = std::snprintf(buffer + length, size - length, ": %.*s",
                                       static_cast<int>(detail.size()), detail.data());
        if (more > 0)
            length = std::min(length + static_cast<std::size_t>(more), size - 1);
    }
    return length;
}

void appendVec3(std::string& out, const Vec3& v)
{
    out.push_back('[');
    for (int k = 0; k < 3; ++k) {
        if (k > 0)
            out.push_back(',');
        appendJsonNumber(out, roundTo(v[k], 4));
    }
    out.push_back(']');
}

} // namespace

std::string reasonMessage(const Reading& reading, std::string_view detail)
{
    std::array<char, 512> buffer{};
    const std::size_t length = formatReasonMessage(reading, detail, buffer.data(), buffer.size());
    return std::string(buffer.data(), length);
}

void appendReadingJson(std::string& out, const ReadingReport& report, int64_t now_ns)
{
    const Reading& reading = report.reading;
    const bool valid = reading.valid && reading.reason == NoReadingReason::None;
    JsonObjectWriter object(out);
    object.field("valid", valid);
    if (valid)
        object.field("distance_m", roundTo(reading.distance_m, 4));
    else
        object.nullField("distance_m");
    if (report.has_frame && reading.reason != NoReadingReason::NoFrameYet) {
        object.field("stamp_ns", reading.stamp_ns);
        if (report.realtime_offset_ns)
            object.field("stamp_realtime_ns",
                         saturatingAddNs(reading.stamp_ns, *report.realtime_offset_ns));
        object.field("age_ms", roundTo(static_cast<double>(now_ns - reading.stamp_ns) / 1e6, 3));
    }
    object.field("frame", reading.frame);
    object.field("valid_fraction", roundTo(reading.valid_fraction, 4));
    object.field("in_range_fraction", roundTo(reading.in_range_fraction, 4));
    object.field("region_pixels", reading.region_pixels);
    object.field("range_limit_fraction", roundTo(reading.range_limit_fraction, 4));
    object.field("inferred_fraction", roundTo(reading.inferred_fraction, 4));
    if (reading.out_of_view_fraction > 0.0)
        object.field("out_of_view_fraction", roundTo(reading.out_of_view_fraction, 4));
    if (reading.calibration_suspect) {
        object.field("calibration_suspect", true);
        object.field("calibration_row_offset_px", roundTo(reading.calibration_row_offset_px, 3));
    }
    if (reading.reason == NoReadingReason::NearerThanRange)
        object.field("nearer_than_m", roundTo(reading.nearer_than_m, 4));
    if (reading.closest_m > 0.0)
        object.field("closest_m", roundTo(reading.closest_m, 4));
    object.field("near_field_guard", reading.near_field_guard);
    if (!valid) {
        const NoReadingReason reason =
            reading.reason == NoReadingReason::None ? NoReadingReason::BadFrame : reading.reason;
        std::string& reason_out = object.openField("reason");
        JsonObjectWriter reason_object(reason_out);
        reason_object.field("code", reasonCode(reason));
        Reading explained = reading;
        explained.reason = reason;
        std::array<char, 512> buffer{};
        const std::size_t length =
            formatReasonMessage(explained, report.detail, buffer.data(), buffer.size());
        reason_object.field("message", std::string_view(buffer.data(), length));
        reason_object.close();
    }
    object.close();
}

Json readingToJson(const ReadingReport& report, int64_t now_ns)
{
    std::string text;
    appendReadingJson(text, report, now_ns);
    return Json::parse(text);
}

void appendCameraPoseJson(std::string& out, const CameraPose& pose)
{
    JsonObjectWriter object(out);
    appendVec3(object.openField("translation_m"), pose.translation_m);
    appendVec3(object.openField("rpy_deg"), pose.rpy_deg);
    object.close();
}

void appendZonesJson(std::string& out, const std::vector<ZoneReading>& zones)
{
    out.push_back('[');
    for (std::size_t i = 0; i < zones.size(); ++i) {
        const ZoneReading& zone = zones[i];
        if (i > 0)
            out.push_back(',');
        JsonObjectWriter object(out);
        object.field("name", zone.name);
        object.field("state", zoneStateName(zone.state));
        if (!zone.reason.empty())
            object.field("reason", zone.reason);
        object.field("points", zone.points);
        if (zone.points > 0) {
            object.field("nearest_m", roundTo(zone.nearest_m, 4));
            appendVec3(object.openField("nearest_point_m"), zone.nearest_point_m);
        }
        appendVec3(object.openField("min_m"), zone.min_m);
        appendVec3(object.openField("max_m"), zone.max_m);
        object.field("visible_fraction", roundTo(zone.visible_fraction, 3));
        object.close();
    }
    out.push_back(']');
}

} // namespace stereod
