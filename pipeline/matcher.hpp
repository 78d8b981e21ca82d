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

namespace stereod {

// What a matcher gives for one pair; buffers are reused when they already have the size.
struct MatchOutput {
    // CV_32FC1, pixels; +inf where no trustworthy match was found (Middlebury convention).
    cv::Mat disparity_px;
    // CV_8UC1: 0 where disparity_px is invalid, else 1..255, how much the match can be
    // trusted (census-sgm: from uniqueness, sharpness of the minimum and left-right
    // agreement; OpenCV's matchers give none: 255 for every reported pixel).
    cv::Mat confidence;
    // CV_8UC1, near-field evidence: a surface may be nearer than the range sees there.
    // 0 none; 1 nearer than the full-resolution range (the best match at its near end, not
    // measured by the extended range); 2 nearer than the extended range (the coarse level's
    // best match at its near end, or the near-field probe's evidence,
    // pipeline/sgm/near_field_probe.hpp). Only census-sgm looks for it; OpenCV's matchers
    // leave it 0 (pipeline/reading_verdict.hpp: their readings say the guard is off).
    cv::Mat near_field;
    // CV_32FC1, in the region compute() watches (the reading's) where disparity_px has
    // none: another estimate, of less precision, that a reading may count when it brings it
    // nearer (census-sgm: its coarse level's match on texture); +inf elsewhere in the
    // region, and outside it unspecified. Empty: the matcher has none (OpenCV's).
    cv::Mat coarse_only_px;
};

class Matcher {
  public:
    virtual ~Matcher() = default;

    // left, right: rectified CV_8UC1 images of the same size. Columns whose whole search
    // range lies outside the right image (x < min_disparity + num_disparities - 1) are
    // invalid for OpenCV's matchers; census-sgm searches the part that is inside and
    // keeps a disparity only well below where the image edge cut the search. watched: the
    // region the reading comes from (pixels), where census-sgm's near-field probe looks
    // and its coarse_only_px is written.
    virtual void compute(const cv::Mat& left, const cv::Mat& right, const cv::Rect& watched,
                         MatchOutput& out) = 0;

    // Whether the matcher gives near-field evidence (MatchOutput::near_field).
    virtual bool nearFieldGuard() const { return false; }

    // Of the last compute()'s time, what census-sgm's extended range and near-field probe
    // took (ms; 0 for the others).
    virtual double extendedRangeMs() const { return 0.0; }
    virtual double nearFieldProbeMs() const { return 0.0; }

    // Applies new parameters of the same matcher kind (and SGBM mode) without rebuilding.
    // The settings must have passed validateMatcherSettings().
    virtual void configure(const MatcherSettings& settings, const DisparityRange& range) = 0;

    // "census-sgm", "bm", "sgbm", "sgbm-3way", "sgbm-hh", "sgbm-hh4".
    virtual std::string name() const = 0;

    virtual MatcherKind kind() const = 0;
};

// Throws SettingsError naming the field ("block_size") and the allowed range when the settings
// cannot work (block size even or out of range, num_disparities not a multiple of 16, ...).
void validateMatcherSettings(const MatcherSettings& settings);

// A matcher of settings.kind searching `range`. Validates first (std::invalid_argument).
std::unique_ptr<Matcher> makeMatcher(const MatcherSettings& settings, const DisparityRange& range);

// The settings of matcher `kind` (and, for SGBM, `mode`; for census-sgm, `tuning`), every
// automatic setting unset: the matcher's own values (effectiveMatcherSettings).
MatcherSettings matcherDefaults(MatcherKind kind, SgbmMode mode = SgbmMode::Sgbm,
                                MatcherTuning tuning = MatcherTuning::Natural);

// The name makeMatcher(settings, ...)->name() will have.
std::string matcherName(const MatcherSettings& settings);

// OpenCV's fixed-point disparity (CV_16SC1, 16 x pixels, invalid marked below
// min_disparity * 16) to pixels (CV_32FC1, invalid = +inf). Columns left of
// min_disparity + num_disparities - 1 are set invalid whatever the matcher left there.
void fixedPointToPixels(const cv::Mat& fixed16, const DisparityRange& range, cv::Mat& disparity_px);

} // namespace stereod
