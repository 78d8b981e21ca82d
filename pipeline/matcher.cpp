#include "pipeline/matcher.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

#include "base/settings_error.hpp"
#include "pipeline/census_sgm_matcher.hpp"
#include "pipeline/matcher_defaults.hpp"

namespace stereod {
namespace {

// OpenCV's matchers return disparities in fixed point with 4 fractional bits.
constexpr int kDisparityScale = cv::StereoMatcher::DISP_SCALE;

[[noreturn]] void invalid(const std::string& key, const std::string& problem)
{
    throw SettingsError(key, problem);
}

void inRange(const std::string& key, int value, int lo, int hi)
{
    if (value < lo || value > hi)
        invalid(key, "must be within " + std::to_string(lo) + ".." + std::to_string(hi) + ", got " +
                         std::to_string(value));
}

int sgbmModeFlag(SgbmMode mode)
{
    switch (mode) {
    case SgbmMode::Sgbm:
        return cv::StereoSGBM::MODE_SGBM;
    case SgbmMode::ThreeWay:
        return cv::StereoSGBM::MODE_SGBM_3WAY;
    case SgbmMode::Hh:
        return cv::StereoSGBM::MODE_HH;
    case SgbmMode::Hh4:
        return cv::StereoSGBM::MODE_HH4;
    }
    return cv::StereoSGBM::MODE_SGBM;
}

// OpenCV's matchers say nothing about how sure they are: every reported pixel gets 255.
void fullConfidenceWhereValid(const cv::Mat& disparity_px, cv::Mat& confidence)
{
    confidence.create(disparity_px.size(), CV_8UC1);
    for (int y = 0; y < disparity_px.rows; ++y) {
        const float* d = disparity_px.ptr<float>(y);
        uint8_t* c = confidence.ptr<uint8_t>(y);
        for (int x = 0; x < disparity_px.cols; ++x)
            c[x] = std::isfinite(d[x]) ? 255 : 0;
    }
}

// Both OpenCV matchers share the fixed-point output and its conversion.
class FixedPointMatcher : public Matcher {
  public:
    void compute(const cv::Mat& left, const cv::Mat& right, const cv::Rect&,
                 MatchOutput& out) override
    {
        CV_Assert(left.type() == CV_8UC1 && right.type() == CV_8UC1 && left.size() == right.size());
        out.near_field.create(left.size(), CV_8UC1);
        out.near_field.setTo(0);
        if (left.cols <= range_.min_disparity + range_.num_disparities - 1) {
            // No column has its whole range inside the right image: nothing can be matched.
            out.disparity_px.create(left.size(), CV_32FC1);
            out.disparity_px.setTo(std::numeric_limits<float>::infinity());
            out.confidence.create(left.size(), CV_8UC1);
            out.confidence.setTo(0);
            return;
        }
        // fixed_ keeps its buffer between frames: create() inside compute() is a no-op.
        engine()->compute(left, right, fixed_);
        fixedPointToPixels(fixed_, range_, out.disparity_px);
        fullConfidenceWhereValid(out.disparity_px, out.confidence);
    }

  protected:
    virtual cv::StereoMatcher* engine() = 0;

    // `s`: with its effective values (effectiveMatcherSettings).
    void setCommon(cv::StereoMatcher& m, const MatcherSettings& s, const DisparityRange& range)
    {
        range_ = range;
        m.setMinDisparity(range.min_disparity);
        m.setNumDisparities(range.num_disparities);
        m.setBlockSize(s.block_size);
        m.setSpeckleWindowSize(*s.speckle_window_px);
        m.setDisp12MaxDiff(*s.lr_max_diff_px);
    }

    DisparityRange range_;
    cv::Mat fixed_; // CV_16SC1, 16 x disparity
};

class BmMatcher final : public FixedPointMatcher {
  public:
    BmMatcher(const MatcherSettings& settings, const DisparityRange& range)
        : bm_(cv::StereoBM::create(range.num_disparities, settings.block_size))
    {
        configure(settings, range);
    }

    void configure(const MatcherSettings& settings, const DisparityRange& range) override
    {
        const MatcherSettings s = effectiveMatcherSettings(settings);
        setCommon(*bm_, s, range);
        // StereoBM compares the speckle range with its fixed-point output as is (SGBM
        // scales it by 16 itself): give it 1/16 px units.
        bm_->setSpeckleRange(*s.speckle_range_px * kDisparityScale);
        bm_->setUniquenessRatio(*s.uniqueness_ratio);
        bm_->setPreFilterCap(s.pre_filter_cap);
        bm_->setTextureThreshold(s.texture_threshold);
    }

    std::string name() const override { return "bm"; }
    MatcherKind kind() const override { return MatcherKind::Bm; }

  protected:
    cv::StereoMatcher* engine() override { return bm_.get(); }

  private:
    cv::Ptr<cv::StereoBM> bm_;
};

class SgbmMatcher final : public FixedPointMatcher {
  public:
    SgbmMatcher(const MatcherSettings& settings, const DisparityRange& range)
        : sgbm_(cv::StereoSGBM::create(range.min_disparity, range.num_disparities,
                                       settings.block_size))
    {
        configure(settings, range);
    }

    void configure(const MatcherSettings& settings, const DisparityRange& range) override
    {
        const MatcherSettings s = effectiveMatcherSettings(settings);
        setCommon(*sgbm_, s, range);
        sgbm_->setSpeckleRange(*s.speckle_range_px); // in pixels: SGBM scales it by 16
        sgbm_->setUniquenessRatio(*s.uniqueness_ratio);
        sgbm_->setPreFilterCap(s.pre_filter_cap);
        sgbm_->setP1(*s.p1);
        sgbm_->setP2(*s.p2);
        sgbm_->setMode(sgbmModeFlag(s.sgbm_mode));
        name_ = matcherName(s);
    }

    std::string name() const override { return name_; }
    MatcherKind kind() const override { return MatcherKind::Sgbm; }

  protected:
    cv::StereoMatcher* engine() override { return sgbm_.get(); }

  private:
    cv::Ptr<cv::StereoSGBM> sgbm_;
    std::string name_;
};

} // namespace

void validateMatcherSettings(const MatcherSettings& settings)
{
    const MatcherSettings s = effectiveMatcherSettings(settings);
    if (s.kind != MatcherKind::Bm && s.kind != MatcherKind::Sgbm &&
        s.kind != MatcherKind::CensusSgm)
        invalid("kind", "unknown matcher");
    if (!s.num_disparities && !(s.min_depth_m > 0.0 && std::isfinite(s.min_depth_m)))
        invalid("min_depth_m", "must be a finite number > 0, got " + std::to_string(s.min_depth_m));
    if (s.num_disparities && (*s.num_disparities <= 0 || *s.num_disparities % 16 != 0))
        invalid("num_disparities", "must be unset (derived from min_depth_m) or a positive "
                                   "multiple of 16, got " +
                                       std::to_string(*s.num_disparities));
    if (s.max_num_disparities <= 0 || s.max_num_disparities % 16 != 0)
        invalid("max_num_disparities",
                "must be a positive multiple of 16, got " + std::to_string(s.max_num_disparities));
    if (s.num_disparities > s.max_num_disparities)
        invalid("num_disparities", std::to_string(*s.num_disparities) +
                                       " exceeds max_num_disparities " +
                                       std::to_string(s.max_num_disparities));
    // Disparities are stored as 16 x d in a 16-bit integer.
    inRange("max_num_disparities", s.max_num_disparities, 16, 1024);
    inRange("min_disparity", s.min_disparity, -1024, 1024);
    if (s.kind == MatcherKind::CensusSgm) {
        validateCensusSgm(settings);
        return;
    }
    if (s.block_size % 2 == 0)
        invalid("block_size", "must be odd, got " + std::to_string(s.block_size));
    if (s.kind == MatcherKind::Bm)
        inRange("block_size", s.block_size, 5, 255);
    else
        // SGBM keeps its path costs in 16 bits: the automatic P2 = 32 * block_size^2 must
        // stay below 32768. (Past about 11 px larger blocks mostly blur depth edges.)
        inRange("block_size", s.block_size, 1, 31);
    inRange("uniqueness_ratio", *s.uniqueness_ratio, 0, 100);
    if (*s.speckle_window_px < 0)
        invalid("speckle_window_px",
                "must be >= 0 (0 disables), got " + std::to_string(*s.speckle_window_px));
    // StereoBM compares it in 1/16 px, so 16 x the range must fit its arithmetic.
    inRange("speckle_range_px", *s.speckle_range_px, 0, 1024);
    if (*s.speckle_window_px > 0 && *s.speckle_range_px == 0)
        invalid("speckle_range_px", "must be >= 1 when speckle_window_px enables the filter");
    inRange("pre_filter_cap", s.pre_filter_cap, 1, 63);
    if (s.texture_threshold < 0)
        invalid("texture_threshold", "must be >= 0, got " + std::to_string(s.texture_threshold));
    // SGBM's 16-bit path costs bound the penalties.
    inRange("p1", *s.p1, 1, 32767);
    inRange("p2", *s.p2, 1, 32767);
    if (s.kind == MatcherKind::Sgbm && *s.p2 <= *s.p1)
        invalid("p2", "must be greater than p1 (" + std::to_string(*s.p2) +
                          " <= " + std::to_string(*s.p1) + ")");
}

std::unique_ptr<Matcher> makeMatcher(const MatcherSettings& settings, const DisparityRange& range)
{
    validateMatcherSettings(settings);
    if (range.num_disparities <= 0 || range.num_disparities % 16 != 0)
        throw std::invalid_argument("disparity range: num_disparities must be a positive "
                                    "multiple of 16, got " +
                                    std::to_string(range.num_disparities));
    if (settings.kind == MatcherKind::CensusSgm)
        return makeCensusSgmMatcher(settings, range);
    if (settings.kind == MatcherKind::Bm)
        return std::make_unique<BmMatcher>(settings, range);
    return std::make_unique<SgbmMatcher>(settings, range);
}

MatcherSettings matcherDefaults(MatcherKind kind, SgbmMode mode, MatcherTuning tuning)
{
    MatcherSettings settings;
    settings.kind = kind;
    settings.sgbm_mode = mode;
    settings.tuning = tuning;
    return settings;
}

std::string matcherName(const MatcherSettings& settings)
{
    if (settings.kind == MatcherKind::CensusSgm && settings.tuning != MatcherTuning::Natural)
        return std::string("census-sgm (") + kMatcherTunings.name(settings.tuning) + ")";
    return std::string(matcherAlgorithmName(settings.kind, settings.sgbm_mode));
}

void fixedPointToPixels(const cv::Mat& fixed16, const DisparityRange& range, cv::Mat& disparity_px)
{
    CV_Assert(fixed16.type() == CV_16SC1);
    disparity_px.create(fixed16.size(), CV_32FC1);
    constexpr float kInvalid = std::numeric_limits<float>::infinity();
    constexpr float kInvScale = 1.0f / static_cast<float>(kDisparityScale);
    // OpenCV marks a rejected pixel with (min_disparity - 1) * 16: anything below the
    // smallest searched disparity is invalid.
    const int lowest_valid = range.min_disparity * kDisparityScale;
    // A column x can be matched only if x - d stays inside the right image for every
    // searched d; further left the matcher could only guess.
    const int first_column =
        std::clamp(range.min_disparity + range.num_disparities - 1, 0, fixed16.cols);
    for (int y = 0; y < fixed16.rows; ++y) {
        const int16_t* src = fixed16.ptr<int16_t>(y);
        float* dst = disparity_px.ptr<float>(y);
        std::fill(dst, dst + first_column, kInvalid);
        for (int x = first_column; x < fixed16.cols; ++x) {
            const int v = src[x];
            dst[x] = v < lowest_valid ? kInvalid : static_cast<float>(v) * kInvScale;
        }
    }
}

} // namespace stereod
