#pragma once
// What the commands of `stereoctl` print and write besides readings: the per-stage latency
// table, and images that depth_io.hpp has no writer for.
//
// Reentrant: no state.

#include <cstdio>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "pipeline/stereo_processor.hpp"

namespace stereod {

// Stage timings as the protocol names them ("rectify", "match", ... in milliseconds).
nlohmann::ordered_json stageTimingsToJson(const StageTimings& timings);

// Prints one row per stage of `stage_ms` (an object of milliseconds; pipeline order
// first, then any other stage the service reports) and a total.
void printStageTable(std::FILE* out, const nlohmann::ordered_json& stage_ms);

// The depth range a colourised picture spans: the 1st to the 99th percentile of the valid
// depths (metres, > 0), so that a few stray pixels do not wash the picture out. (1, 10)
// when there is no valid depth.
std::pair<double, double> depthDisplayRange(const cv::Mat& depth_m);

// Writes an 8-bit image as PNG. Throws std::runtime_error naming the file.
void writeImagePng(const std::string& path, const cv::Mat& image);

} // namespace stereod
