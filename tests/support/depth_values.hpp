#pragma once
// Depth decoded by an independent client (a JSON array of metres, null for NaN, as the
// node scripts print it) held to the service's own millimetre depth of the same pair.

#include <cstddef>

#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

namespace stereod::test {

struct DepthAgreement {
    std::size_t with_depth = 0; // pixels the service gives a depth
    std::size_t mismatched = 0; // pixels that differ: NaN against a depth, or over 1 mm apart
};

// `depth_mm`: CV_16UC1, 0 = none; `metres`: one value per pixel, row after row.
DepthAgreement compareDepth(const cv::Mat& depth_mm, const nlohmann::ordered_json& metres);

} // namespace stereod::test
