// The commands that work without the service: depth (one pair through the service's
// StereoProcessor) and calibrate.

#include <charconv>
#include <cstdio>
#include <filesystem>
#include <string_view>
#include <system_error>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "config/service_config.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "ctl/output.hpp"
#include "ctl/reading_format.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/census_sgm_matcher.hpp"
#include "pipeline/depth_io.hpp"
#include "pipeline/stereo_processor.hpp"
#include "protocol/reading_json.hpp"

namespace stereod {

namespace {

using json = nlohmann::ordered_json;

std::vector<std::string_view> split(std::string_view text, char separator)
{
    std::vector<std::string_view> parts;
    for (;;) {
        const std::size_t at = text.find(separator);
        parts.push_back(text.substr(0, at));
        if (at == std::string_view::npos) {
            return parts;
        }
        text.remove_prefix(at + 1);
    }
}

template <typename T> bool parseNumber(std::string_view text, T& value)
{
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    return error == std::errc() && end == text.data() + text.size();
}

// "640x480" -> 640 x 480 pixels.
cv::Size parseSize(const std::string& text, const char* option)
{
    const auto parts = split(text, 'x');
    int width = 0;
    int height = 0;
    if (parts.size() != 2 || !parseNumber(parts[0], width) || !parseNumber(parts[1], height) ||
        width <= 0 || height <= 0) {
        throw UsageError(fmt::format("{}: expected WIDTHxHEIGHT in pixels (e.g. 640x480), got '{}'",
                                     option, text));
    }
    return {width, height};
}

// "x,y,w,h", fractions of the image, the rectangle inside it.
RegionOfInterest parseRoi(const std::string& text)
{
    const auto parts = split(text, ',');
    RegionOfInterest roi;
    const bool parsed = parts.size() == 4 && parseNumber(parts[0], roi.x) &&
                        parseNumber(parts[1], roi.y) && parseNumber(parts[2], roi.width) &&
                        parseNumber(parts[3], roi.height);
    if (!parsed || roi.x < 0.0 || roi.y < 0.0 || roi.width <= 0.0 || roi.height <= 0.0 ||
        roi.x + roi.width > 1.0 || roi.y + roi.height > 1.0) {
        throw UsageError(fmt::format("--roi: expected x,y,w,h as fractions of the image with the "
                                     "rectangle inside it (e.g. 0.25,0.25,0.5,0.5), got '{}'",
                                     text));
    }
    return roi;
}

cv::Mat readGray(const std::string& path)
{
    std::error_code error;
    if (!std::filesystem::is_regular_file(path, error)) {
        throw UsageError(fmt::format("cannot read image {}: {}", path,
                                     error ? error.message() : "no such file"));
    }
    cv::Mat image;
    try {
        image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    } catch (const cv::Exception& e) {
        throw UsageError(fmt::format("cannot read image {}: {}", path, e.what()));
    }
    if (image.empty()) {
        throw UsageError(fmt::format("cannot read image {}: not an image format OpenCV decodes, or "
                                     "corrupt",
                                     path));
    }
    return image;
}

// The colour of an image file as BGR, or an empty Mat when the file is grey (or has no
// colour OpenCV decodes): the cloud's colours. The file was read once as grey already
// (readGray), which stays what the matcher sees.
cv::Mat readColour(const std::string& path)
{
    cv::Mat image;
    try {
        image = cv::imread(path, cv::IMREAD_ANYCOLOR);
    } catch (const cv::Exception& e) {
        throw UsageError(fmt::format("cannot read image {}: {}", path, e.what()));
    }
    if (image.channels() == 4)
        cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
    return image.channels() == 3 ? image : cv::Mat();
}

ProcessorSettings depthSettings(const DepthOptions& options)
{
    // The service's own processing: its built-in defaults, or those of a configuration.
    ProcessorSettings settings = options.config_path.empty()
                                     ? defaultConfig().processing
                                     : loadConfig(options.config_path).processing;
    MatcherSettings& matcher = settings.matcher;
    const MatcherKind configured = matcher.kind;
    // --matcher is one of kMatcherAlgorithms' names (the option checks), or empty.
    if (const auto algorithm = matcherAlgorithmNamed(options.matcher)) {
        matcher.kind = algorithm->kind;
        matcher.sgbm_mode = algorithm->mode;
    }
    const MatcherTuning configured_tuning = matcher.tuning;
    // --tuning is one of kMatcherTunings' names (the option checks), or empty.
    if (const auto tuning = kMatcherTunings.parse(options.tuning))
        matcher.tuning = *tuning;
    // Switched from census-sgm to OpenCV's or back here, or to another tuning: the new
    // matcher's (tuning's) own values for the settings they share.
    if ((configured == MatcherKind::CensusSgm) != (matcher.kind == MatcherKind::CensusSgm) ||
        configured_tuning != matcher.tuning) {
        matcher.uniqueness_ratio.reset();
        matcher.speckle_window_px.reset();
        matcher.speckle_range_px.reset();
        matcher.lr_max_diff_px.reset();
    }
    if (options.min_depth_m) {
        matcher.min_depth_m = *options.min_depth_m;
        matcher.num_disparities.reset(); // derived from the closest depth
    }
    if (options.max_disparity) {
        constexpr int kStep = 16; // the matchers search multiples of 16 disparities
        matcher.num_disparities = (*options.max_disparity + kStep - 1) / kStep * kStep;
    }
    if (!options.roi.empty()) {
        settings.nearest.roi = parseRoi(options.roi);
    }
    settings.compute_cloud = !options.cloud_path.empty();
    return settings;
}

StereoCalibration rectifiedCalibration(const RectifiedOptions& geometry, cv::Size image_size)
{
    return makeRectifiedCalibration(image_size, geometry.focal_px.value(),
                                    geometry.baseline_m.value(), geometry.cx_px, geometry.cy_px,
                                    geometry.doffs_px);
}

StereoCalibration depthCalibration(const DepthOptions& options, cv::Size image_size)
{
    if (!options.calib_path.empty()) {
        return loadCalibration(options.calib_path);
    }
    if (!options.geometry.rectified) {
        throw UsageError("give --calib FILE, or --rectified --focal-px F --baseline-m B for a "
                         "rectified pair");
    }
    return rectifiedCalibration(options.geometry, image_size);
}

// The protocol's reading object for a reading made just now from a pair without a capture
// time: stamp 0, age 0.
json offlineReadingJson(const Reading& reading)
{
    ReadingReport report;
    report.reading = reading;
    return readingToJson(report, /*now_ns=*/reading.stamp_ns);
}

json disparityRangeToJson(const DisparityRange& range)
{
    return {{"min_disparity", range.min_disparity},
            {"num_disparities", range.num_disparities},
            {"closest_depth_m", range.closest_depth_m},
            {"extended_range", range.extended},
            {"full_resolution_closest_depth_m", range.range_closest_depth_m},
            {"capped", range.capped}};
}

void printDepthReport(const DepthResult& result, const DisparityRange& range,
                      const std::string& matcher)
{
    const Reading& reading = result.reading;
    if (reading.valid) {
        fmt::print("nearest: {:.3f} m\n", reading.distance_m);
    } else {
        fmt::print("no reading: {}\n", reasonMessage(reading));
    }
    fmt::print("  region {} px, {:.1f} % valid, {:.1f} % in range\n", reading.region_pixels,
               100.0 * reading.valid_fraction, 100.0 * reading.in_range_fraction);
    if (reading.out_of_view_fraction > 0.0)
        fmt::print("  {} (nearest.roi.x or --roi further right sees it whole)\n",
                   leftEdgeNote(reading.out_of_view_fraction));
    fmt::print("matcher {}, disparities {}..{}{}, closest measured depth {:.3f} m{}\n", matcher,
               range.min_disparity, range.min_disparity + range.num_disparities - 1,
               range.extended ? fmt::format(" (extended to {})", range.last_disparity_px) : "",
               range.closest_depth_m,
               range.capped ? " (capped: the configured closest depth is out of sight)" : "");
    printStageTable(stdout, stageTimingsToJson(result.timings));
    if (range.extended)
        fmt::print("  of match: extended range {:.2f} ms, near-field probe {:.2f} ms\n",
                   result.timings.extended_range_ms, result.timings.near_field_probe_ms);
}

} // namespace

int runDepth(const DepthOptions& options)
{
    const cv::Mat left = readGray(options.left_path);
    const cv::Mat right = readGray(options.right_path);
    if (left.size() != right.size()) {
        throw UsageError(fmt::format("the images differ in size: {} is {}x{}, {} is {}x{}",
                                     options.left_path, left.cols, left.rows, options.right_path,
                                     right.cols, right.rows));
    }
    const ProcessorSettings settings = depthSettings(options);
    const StereoCalibration calibration = depthCalibration(options, left.size());
    checkFrameSize(calibration, left.size(), options.left_path);

    StereoProcessor processor(calibration, settings);
    DepthResult result;
    const cv::Mat left_colour = readColour(options.left_path);
    processor.process(left, left_colour, right, /*stamp_ns=*/0, /*frame=*/0, result);
    const DisparityRange range = processor.disparityRange();

    // In the order written, which is the order they are reported in.
    std::vector<std::pair<std::string, std::string>> written;
    if (!options.disparity_path.empty()) {
        writeDisparity(options.disparity_path, result.disparity);
        written.emplace_back("disparity", options.disparity_path);
    }
    if (!options.depth_path.empty()) {
        writeDepthPng(options.depth_path, result.depth_m);
        written.emplace_back("depth", options.depth_path);
    }
    if (!options.cloud_path.empty()) {
        writePly(options.cloud_path, result.cloud, result.cloud_colour);
        written.emplace_back("cloud", options.cloud_path);
    }
    if (!options.colormap_path.empty()) {
        const auto [near_m, far_m] = depthDisplayRange(result.depth_m);
        writeColorizedDepth(options.colormap_path, result.depth_m, near_m, far_m);
        written.emplace_back("colormap", options.colormap_path);
    }
    if (!options.confidence_path.empty()) {
        writeConfidencePng(options.confidence_path, result.confidence);
        written.emplace_back("confidence", options.confidence_path);
    }

    if (options.json) {
        json files = json::object();
        for (const auto& [kind, path] : written) {
            files[kind] = path;
        }
        json timings = stageTimingsToJson(result.timings);
        timings["total"] = result.timings.totalMs();
        const json out = {{"reading", offlineReadingJson(result.reading)},
                          {"timings_ms", timings},
                          {"match_parts_ms",
                           {{"extended_range", result.timings.extended_range_ms},
                            {"near_field_probe", result.timings.near_field_probe_ms}}},
                          {"disparity_range", disparityRangeToJson(range)},
                          {"matcher", processor.matcherName()},
                          {"image", {{"width", left.cols}, {"height", left.rows}}},
                          {"cloud_points", result.cloud.size()},
                          {"files", files}};
        fmt::print("{}\n", out.dump(2));
    } else {
        printDepthReport(result, range, processor.matcherName());
        for (const auto& [kind, path] : written) {
            fmt::print("wrote {} {}\n", kind, path);
        }
    }
    return result.reading.valid ? kExitOk : kExitNoReading;
}

int runCalibrate(const CalibrateOptions& options)
{
    if (options.live) {
        return runLiveCalibration(options);
    }
    if (!options.from_ros.empty()) {
        return runCalibrationImport(options, {});
    }
    if (!options.from_opencv.empty()) {
        return runCalibrationImport(options, parseSize(options.size, "--size"));
    }
    if (!options.geometry.rectified) {
        return runChessboardCalibration(options);
    }
    const cv::Size size = parseSize(options.size, "--size");
    const StereoCalibration calibration = rectifiedCalibration(options.geometry, size);
    saveCalibration(calibration, options.out_path);
    const RectifiedGeometry& g = calibration.rectified;
    fmt::print("wrote rectified calibration {}: {}x{}, f {:.3f} px, B {:.4f} m, c ({:.2f}, {:.2f}) "
               "px, doffs {:.3f} px\n",
               options.out_path, g.image_size.width, g.image_size.height, g.focal_px, g.baseline_m,
               g.cx_px, g.cy_px, g.doffs_px);
    return kExitOk;
}

} // namespace stereod
