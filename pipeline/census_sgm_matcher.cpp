#include "pipeline/census_sgm_matcher.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

#include <sched.h>

#include "base/settings_error.hpp"
#include "pipeline/matcher_defaults.hpp"

namespace stereod {
namespace {

class CensusSgmMatcher final : public Matcher {
  public:
    CensusSgmMatcher(const MatcherSettings& settings, const DisparityRange& range)
    {
        configure(settings, range);
    }

    void compute(const cv::Mat& left, const cv::Mat& right, const cv::Rect& watched,
                 MatchOutput& out) override
    {
        CV_Assert(left.type() == CV_8UC1 && right.type() == CV_8UC1 && left.size() == right.size());
        if (!core_ || core_->settings().full.width != left.cols ||
            core_->settings().full.height != left.rows) {
            sgm::PyramidSgmSettings sized = settings_;
            sized.full.width = left.cols;
            sized.full.height = left.rows;
            core_ = std::make_unique<sgm::PyramidSgm>(sized);
        }
        out.disparity_px.create(left.size(), CV_32FC1);
        out.confidence.create(left.size(), CV_8UC1);
        out.near_field.create(left.size(), CV_8UC1);
        if (settings_.extended_range)
            out.coarse_only_px.create(left.size(), CV_32FC1);
        else
            out.coarse_only_px.release();
        CV_Assert(out.disparity_px.isContinuous() && out.confidence.isContinuous() &&
                  out.near_field.isContinuous() &&
                  (out.coarse_only_px.empty() || out.coarse_only_px.isContinuous()));
        core_->compute(left.data, left.step, right.data, right.step,
                       {watched.x, watched.y, watched.width, watched.height},
                       {out.disparity_px.ptr<float>(), out.confidence.ptr<uint8_t>(),
                        out.near_field.ptr<uint8_t>(),
                        out.coarse_only_px.empty() ? nullptr : out.coarse_only_px.ptr<float>()});
    }

    void configure(const MatcherSettings& settings, const DisparityRange& range) override
    {
        settings_ = pyramidSgmSettings(settings, range);
        sgm::validatePyramidSgmSettings(settings_);
        name_ = matcherName(settings);
        core_.reset(); // rebuilt, with its buffers, on the next pair
    }

    std::string name() const override { return name_; }
    MatcherKind kind() const override { return MatcherKind::CensusSgm; }
    bool nearFieldGuard() const override { return settings_.near_field_probe; }
    double extendedRangeMs() const override { return core_ ? core_->timings().extended_ms : 0.0; }
    double nearFieldProbeMs() const override { return core_ ? core_->timings().probe_ms : 0.0; }

  private:
    sgm::PyramidSgmSettings settings_;
    std::string name_; // with the tuning, when it is not the default
    std::unique_ptr<sgm::PyramidSgm> core_;
};

} // namespace

int availableCores()
{
    cpu_set_t set;
    CPU_ZERO(&set);
    if (sched_getaffinity(0, sizeof(set), &set) == 0)
        return std::max(1, CPU_COUNT(&set));
    return 1;
}

sgm::CensusSgmSettings censusSgmSettings(const MatcherSettings& settings,
                                         const DisparityRange& range)
{
    // The tuning also sets core fields the configuration does not reach (gap filling,
    // textured cost, periodic patterns); every setting it does reach is set by now.
    const MatcherSettings s = effectiveMatcherSettings(settings);
    sgm::CensusSgmSettings c = censusSgmTuning(s.tuning);
    c.width = 0;
    c.height = 0;
    c.min_disparity = range.min_disparity;
    c.num_disparities = range.num_disparities;
    c.census_width = *s.census_width;
    c.census_height = *s.census_height;
    c.paths = *s.paths;
    c.p1 = *s.p1;
    c.p2 = *s.p2;
    c.p2_gradient_scale = *s.p2_gradient_scale;
    c.uniqueness_percent = *s.uniqueness_ratio;
    c.lr_max_diff_px = *s.lr_max_diff_px;
    c.speckle_window_px = *s.speckle_window_px;
    c.speckle_range_px = *s.speckle_range_px;
    c.threads = *s.threads;
    return c;
}

sgm::PyramidSgmSettings pyramidSgmSettings(const MatcherSettings& settings,
                                           const DisparityRange& range)
{
    sgm::PyramidSgmSettings p;
    p.full = censusSgmSettings(settings, range);
    p.extended_range = settings.extended_range;
    p.guided_search = settings.guided_search;
    if (settings.guided_max_share)
        p.guided_max_share = *settings.guided_max_share;
    p.near_field_probe = true;
    return p;
}

void validateCensusSgm(const MatcherSettings& settings)
{
    DisparityRange range;
    range.min_disparity = settings.min_disparity;
    // The range comes from the calibration later; any valid count checks the rest.
    range.num_disparities = settings.num_disparities.value_or(16);
    const std::string most = "census-sgm searches at most " + std::to_string(sgm::kMaxDisparities) +
                             " disparities, got ";
    if (settings.num_disparities > sgm::kMaxDisparities)
        throw SettingsError("num_disparities", most + std::to_string(*settings.num_disparities));
    if (!settings.num_disparities && settings.max_num_disparities > sgm::kMaxDisparities)
        throw SettingsError("max_num_disparities",
                            most + std::to_string(settings.max_num_disparities));
    sgm::validatePyramidSgmSettings(pyramidSgmSettings(settings, range));
}

std::unique_ptr<Matcher> makeCensusSgmMatcher(const MatcherSettings& settings,
                                              const DisparityRange& range)
{
    return std::make_unique<CensusSgmMatcher>(settings, range);
}

} // namespace stereod
