// `stereoctl check-calibration`: calibration health (pipeline/calibration_health.hpp) on a
// rig's raw pairs, offline, and the correction when asked for. A rectified-only
// calibration checks the pairs as they come (identity rectification), and its correction
// is written as a full calibration.

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "ctl/client.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "ctl/file_patterns.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/calibration_health.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/rectifier.hpp"

namespace stereod {

namespace {

using json = nlohmann::ordered_json;

cv::Mat readGray(const std::string& path, cv::Size expected)
{
    const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (image.empty())
        throw UsageError(fmt::format("{}: cannot read the image", path));
    if (image.size() != expected)
        throw UsageError(fmt::format("{}: the image is {}x{}, the calibration is for {}x{}", path,
                                     image.cols, image.rows, expected.width, expected.height));
    return image;
}

struct PairFigures {
    std::string left, right;
    HealthMeasurement measurement;
};

std::vector<PairFigures> measurePairs(const StereoCalibration& calibration,
                                      const std::vector<std::string>& left,
                                      const std::vector<std::string>& right)
{
    const Rectifier rectifier(calibration);
    CalibrationHealthChecker checker(calibration.rectified);
    std::vector<PairFigures> pairs;
    cv::Mat left_rect, right_rect;
    for (size_t i = 0; i < left.size(); ++i) {
        const cv::Size size = toCv(calibration.rectified.image_size);
        rectifier.rectifyLeft(readGray(left[i], size), left_rect);
        rectifier.rectifyRight(readGray(right[i], size), right_rect);
        pairs.push_back({left[i], right[i], checker.measure(left_rect, right_rect)});
    }
    return pairs;
}

json figuresJson(const HealthMeasurement& m)
{
    json out;
    out["state"] = healthStateName(m.state);
    if (!m.reason.empty())
        out["reason"] = m.reason;
    out["row_offset_px"] = m.row_offset_px;
    out["row_offset_p90_px"] = m.row_offset_p90_px;
    out["matches"] = m.matches;
    out["negative_disparity_fraction"] = m.negative_disparity_fraction;
    out["offset_px"] = m.model.offset_px;
    out["roll_deg"] = m.model.roll_deg;
    out["max_row_error_px"] = m.model.max_row_error_px;
    out["yaw_deg"] = m.model.yaw_deg;
    out["vertical_scale"] = m.model.vertical_scale;
    out["residual_px"] = m.model.residual_px;
    return out;
}

std::string figuresLine(const HealthMeasurement& m)
{
    std::string line = healthStateName(m.state);
    if (!m.reason.empty())
        line += " (" + m.reason + ")";
    return line + fmt::format(": {} matches, rows up to {:.2f} px apart (right - left {:+.2f} px "
                              "at the centre, roll {:+.3f} deg); median {:+.2f} px, 90 % within "
                              "{:.2f} px",
                              m.matches, m.model.max_row_error_px, m.model.offset_px,
                              m.model.roll_deg, m.row_offset_px, m.row_offset_p90_px);
}

// What the figures mean for depth, in one sentence.
std::string meaning(const HealthMeasurement& m)
{
    switch (m.state) {
    case HealthState::Ok:
        return "matching points lie on the same rows: the calibration still rectifies this rig";
    case HealthState::Degraded:
        return m.reason == "roll"
                   ? "the right image is turned against the left: the rows drift apart towards "
                     "the sides, the matcher compares the wrong rows there; recalibrate, or try "
                     "--fix"
                   : "the rows of matching points have drifted apart: the matcher compares the "
                     "wrong rows, finds fewer matches and wronger depths; recalibrate, or try "
                     "--fix";
    case HealthState::Failed:
        return m.reason == "cameras_swapped"
                   ? "most matches have a negative disparity: the left and right cameras are "
                     "swapped (check the device order)"
                   : "the rows are far apart: depth from this calibration cannot be trusted; "
                     "recalibrate";
    case HealthState::Unknown:
        return "too few features matched (no texture?): no verdict";
    }
    return {};
}

int exitCodeFor(HealthState state)
{
    switch (state) {
    case HealthState::Ok:
        return kExitOk;
    case HealthState::Degraded:
    case HealthState::Failed:
        return kExitNoReading;
    case HealthState::Unknown:
        return kExitUsage;
    }
    return kExitUsage;
}

// The running service's calibration health, from its status.
int checkRunningService(const CheckCalibrationOptions& options)
{
    ProtocolClient client(options.service.socket_path,
                          std::chrono::milliseconds(options.service.timeout_ms));
    const json reply = client.request({{"cmd", "status"}});
    const json status = reply.value("status", json::object());
    const json health = status.value("calibration_health", json::object());
    const std::string state = health.value("state", std::string("unknown"));
    if (options.json) {
        std::printf("%s\n", health.dump(2).c_str());
    } else {
        std::printf("%s", state.c_str());
        if (health.contains("reason"))
            std::printf(" (%s)", health["reason"].get<std::string>().c_str());
        if (health.contains("max_row_error_px"))
            std::printf(": %d matches, rows up to %.2f px apart (right - left %+.2f px at the "
                        "centre, roll %+.3f deg); median %+.2f px, 90 %% within %.2f px, trend "
                        "%+.3f px/min; last check %s, checked %.1f s ago, %llu state changes",
                        health.value("matches", 0), health.value("max_row_error_px", 0.0),
                        health.value("offset_px", 0.0), health.value("roll_deg", 0.0),
                        health.value("row_offset_px", 0.0), health.value("row_offset_p90_px", 0.0),
                        health.value("trend_px_per_min", 0.0),
                        health.value("last_check", std::string("unknown")).c_str(),
                        health.value("checked_age_s", 0.0),
                        static_cast<unsigned long long>(health.value("state_changes", 0ULL)));
        std::printf("\n");
    }
    const std::optional<HealthState> parsed = kHealthStates.parse(state);
    if (parsed == HealthState::Ok)
        return kExitOk;
    if (parsed == HealthState::Degraded || parsed == HealthState::Failed)
        return kExitNoReading;
    return kExitUsage;
}

} // namespace

int runCheckCalibration(const CheckCalibrationOptions& options)
{
    if (options.left_glob.empty())
        return checkRunningService(options);
    const std::vector<std::string> left = expandGlob(options.left_glob, "--left");
    const std::vector<std::string> right = expandGlob(options.right_glob, "--right");
    if (left.size() != right.size())
        throw UsageError(fmt::format("--left matches {} files and --right {}: they must pair up",
                                     left.size(), right.size()));
    if (options.fix) {
        namespace fs = std::filesystem;
        std::error_code ignored;
        if (fs::exists(options.out_path))
            throw UsageError(fmt::format("--out {}: exists already; the correction goes to a new "
                                         "file, nothing is overwritten",
                                         options.out_path));
        if (fs::equivalent(options.out_path, options.calib_path, ignored))
            throw UsageError("--out must not be the checked calibration");
    }
    const StereoCalibration calibration = loadCalibration(options.calib_path);
    const bool rectified_only = calibration.kind == StereoCalibration::Kind::RectifiedOnly;

    const std::vector<PairFigures> pairs = measurePairs(calibration, left, right);
    std::vector<HealthMeasurement> all;
    for (const PairFigures& p : pairs)
        all.push_back(p.measurement);
    const CalibrationHealthChecker pooler(calibration.rectified);
    const HealthMeasurement overall = pooler.pool(all);

    json out = figuresJson(overall);
    json per_pair = json::array();
    for (const PairFigures& p : pairs) {
        json entry = figuresJson(p.measurement);
        entry["left"] = p.left;
        entry["right"] = p.right;
        per_pair.push_back(entry);
        if (!options.json)
            std::printf("%s %s: %s\n", fileName(p.left).c_str(), fileName(p.right).c_str(),
                        figuresLine(p.measurement).c_str());
    }
    out["pairs"] = per_pair;
    if (!options.json) {
        std::printf("overall, %zu pairs: %s\n%s\n", pairs.size(), figuresLine(overall).c_str(),
                    meaning(overall).c_str());
    }

    if (options.fix) {
        cv::Vec2d degrees;
        const StereoCalibration corrected =
            correctRightRotation(calibration, overall.used, &degrees);
        std::vector<HealthMeasurement> after_all;
        for (const PairFigures& p : measurePairs(corrected, left, right))
            after_all.push_back(p.measurement);
        const HealthMeasurement after = pooler.pool(after_all);
        saveCalibration(corrected, options.out_path);
        json fix;
        fix["out"] = options.out_path;
        fix["kind"] = "full";
        fix["pitch_deg"] = degrees[0];
        fix["roll_deg"] = degrees[1];
        fix["before"] = figuresJson(overall);
        fix["after"] = figuresJson(after);
        out["fix"] = fix;
        if (!options.json)
            std::printf("correction: right camera turned %+.4f deg about x (pitch), %+.4f deg "
                        "about z (roll); depth unchanged\nrows up to %.2f px apart before (roll "
                        "%+.3f deg), %.2f px after (roll %+.3f deg): %s\nwrote %s%s\n",
                        degrees[0], degrees[1], overall.model.max_row_error_px,
                        overall.model.roll_deg, after.model.max_row_error_px, after.model.roll_deg,
                        healthStateName(after.state), options.out_path.c_str(),
                        rectified_only ? " (a full calibration: the rectified-only form has no "
                                         "rotation to correct)"
                                       : "");
    }
    if (options.json)
        std::printf("%s\n", out.dump(2).c_str());
    return exitCodeFor(overall.state);
}

} // namespace stereod
