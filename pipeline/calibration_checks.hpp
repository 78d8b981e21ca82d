// The checks of a stereo calibration (sizes, a rotation that is one, the projections
// agreeing with R and T), shared by the YAML loader, which knows each key's line, and
// by calibrations assembled in code. Internal to pipeline/'s calibration files.
#pragma once

#include <map>
#include <string>

#include "pipeline/calibration.hpp"

namespace stereod::calibration_detail {

// Line (1-based) of each key seen while parsing, so that validation after parsing can
// still point at the place in the file.
using KeyLines = std::map<std::string, int>;

std::string describeSize(cv::Size size);
// Shortest text that reads back to the same double.
std::string formatNumber(double value);
[[noreturn]] void fail(const std::string& origin, int line, const std::string& key,
                       const std::string& problem);

// Throws CalibrationError naming the first problem, at its key's line when `lines` has it.
void checkCalibration(const StereoCalibration& calibration, const std::string& origin,
                      const KeyLines& lines);

} // namespace stereod::calibration_detail
