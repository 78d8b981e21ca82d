#pragma once
// The real scenes of the shared data with their ground-truth disparity (Middlebury 2001,
// 2005, 2014, KITTI 2012, ETH3D: shared/data/README.md), read in place, for the tests that
// score matchers and readings against them.

#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace stereod::test {

struct SceneTruth {
    std::string name;
    std::string left_path, right_path, truth_path;
    double divisor = 1.0; // ground truth value / divisor = disparity; 0 or inf unknown
};

// Every scene found under the shared data (17 when all are there).
std::vector<SceneTruth> scenesWithTruth();

// The scene's true disparities in pixels (CV_32FC1), 0 where unknown.
cv::Mat loadTruthPx(const SceneTruth& scene);

// The reference's disparity range: the largest true disparity x 1.05, in steps of 16.
int referenceRange(const cv::Mat& truth_px);

} // namespace stereod::test
