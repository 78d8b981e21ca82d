// `stereoctl check-calibration`: calibration health (pipeline/calibration_health.hpp) on a
// rig's raw pairs, offline, and the correction when asked for.

#include <chrono>
#include <cstdio>
#include <filesystem>
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
    CalibrationHealthChecker checker;
    std::vector<PairFigures> pairs;
    cv::Mat left_rect, right_rect;
    for (size_t i = 0; i < left.size(); ++i) {
        const cv::Size size = calibration.rectified.image_size;
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
    return out;
}

std::string figuresLine(const HealthMeasurement& m)
{
    std::string line = healthStateName(m.state);
    if (!m.reason.empty())
        line += " (" + m.reason + ")";
    return line + fmt::format(": {} matches, row offset {:+.2f} px (right - left), 90 % within "
                              "{:.2f} px",
                              m.matches, m.row_offset_px, m.row_offset_p90_px);
}

// What the figures mean for depth, in one sentence.
std::string meaning(const HealthMeasurement& m)
{
    switch (m.state) {
    case HealthState::Ok:
        return "matching points lie on the same rows: the calibration still rectifies this rig";
    case HealthState::Degraded:
        return "the rows of matching points have drifted apart: the matcher compares the wrong "
               "rows, finds fewer matches and wronger depths; recalibrate, or try --fix";
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
        if (health.contains("row_offset_px"))
            std::printf(": %d matches, row offset %+.2f px (right - left), 90 %% within %.2f px, "
                        "trend %+.3f px/min, checked %.1f s ago",
                        health.value("matches", 0), health.value("row_offset_px", 0.0),
                        health.value("row_offset_p90_px", 0.0),
                        health.value("trend_px_per_min", 0.0), health.value("checked_age_s", 0.0));
        std::printf("\n");
    }
    if (state == "ok")
        return kExitOk;
    if (state == "degraded" || state == "failed")
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
    if (calibration.kind != StereoCalibration::Kind::Full)
        throw UsageError(fmt::format("{}: a rectified-only calibration has no rectification to "
                                     "check; the pairs are taken as rectified already",
                                     options.calib_path));

    const std::vector<PairFigures> pairs = measurePairs(calibration, left, right);
    std::vector<HealthMeasurement> all;
    for (const PairFigures& p : pairs)
        all.push_back(p.measurement);
    const HealthSettings settings;
    const HealthMeasurement overall = poolMeasurements(all, settings);

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
        const HealthMeasurement after = poolMeasurements(after_all, settings);
        saveCalibration(corrected, options.out_path);
        json fix;
        fix["out"] = options.out_path;
        fix["pitch_deg"] = degrees[0];
        fix["roll_deg"] = degrees[1];
        fix["before"] = figuresJson(overall);
        fix["after"] = figuresJson(after);
        out["fix"] = fix;
        if (!options.json)
            std::printf("correction: right camera turned %+.4f deg about x (pitch), %+.4f deg "
                        "about z (roll); depth unchanged\nrow offset before %+.2f px (90 %% within "
                        "%.2f px), after %+.2f px (90 %% within %.2f px)\nwrote %s\n",
                        degrees[0], degrees[1], overall.row_offset_px, overall.row_offset_p90_px,
                        after.row_offset_px, after.row_offset_p90_px, options.out_path.c_str());
    }
    if (options.json)
        std::printf("%s\n", out.dump(2).c_str());
    return exitCodeFor(overall.state);
}

} // namespace stereod
