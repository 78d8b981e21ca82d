#pragma once
// Correspondence search: for every pixel of the rectified left image, its disparity d,
// such that the same scene point lies at x - d on the same row of the rectified right
// image (Middlebury convention).
//
// Matchers are thread-bound: each keeps its working buffers between calls, so one
// instance serves one thread. (OpenCV may use its own thread pool inside compute().)

#include <memory>
#include <string>

#include <opencv2/core/mat.hpp>

#include "pipeline/matcher_settings.hpp"
#include "pipeline/stereo_processor.hpp"

namespace stereod {

class Matcher {
public:
    virtual ~Matcher() = default;

    // left, right: rectified CV_8UC1 images of the same size.
    // disparity_px: CV_32FC1 of that size, in pixels; +inf where no trustworthy match was
    // found (Middlebury convention), including the left-most min_disparity +
    // num_disparities - 1 columns, whose full disparity range lies outside the right image.
    // Reuses disparity_px when it already has the right size and type.
    virtual void compute(const cv::Mat& left, const cv::Mat& right, cv::Mat& disparity_px) = 0;

    // Applies new parameters of the same matcher kind (and SGBM mode) without rebuilding.
    // The settings must have passed validateMatcherSettings().
    virtual void configure(const MatcherSettings& settings, const DisparityRange& range) = 0;

    // "bm", "sgbm", "sgbm-3way", "sgbm-hh", "sgbm-hh4".
    virtual std::string name() const = 0;

    virtual MatcherKind kind() const = 0;
};

// Throws std::invalid_argument naming the setting and the allowed range when the settings
// cannot work (block size even or out of range, num_disparities not a multiple of 16, ...).
void validateMatcherSettings(const MatcherSettings& settings);

// A matcher of settings.kind searching `range`. Validates first (std::invalid_argument).
std::unique_ptr<Matcher> makeMatcher(const MatcherSettings& settings, const DisparityRange& range);

// The name makeMatcher(settings, ...)->name() will have.
std::string matcherName(const MatcherSettings& settings);

// OpenCV's fixed-point disparity (CV_16SC1, 16 x pixels, invalid marked below
// min_disparity * 16) to pixels (CV_32FC1, invalid = +inf). Columns left of
// min_disparity + num_disparities - 1 are set invalid whatever the matcher left there.
void fixedPointToPixels(const cv::Mat& fixed16, const DisparityRange& range, cv::Mat& disparity_px);

} // namespace stereod
