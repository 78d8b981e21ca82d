#include "pipeline/matcher_defaults.hpp"

#include <algorithm>

#include "pipeline/census_sgm_matcher.hpp"

namespace stereod {
namespace {

void setIfUnset(std::optional<int>& setting, int value)
{
    if (!setting)
        setting = value;
}

} // namespace

int automaticMatcherThreads()
{
    return std::min(availableCores(), 8);
}

MatcherSettings effectiveMatcherSettings(const MatcherSettings& settings)
{
    MatcherSettings s = settings;
    if (s.kind == MatcherKind::CensusSgm) {
        const sgm::CensusSgmSettings& tuned = censusSgmTuning(s.tuning);
        setIfUnset(s.uniqueness_ratio, tuned.uniqueness_percent);
        setIfUnset(s.speckle_window_px, tuned.speckle_window_px);
        setIfUnset(s.speckle_range_px, tuned.speckle_range_px);
        setIfUnset(s.lr_max_diff_px, tuned.lr_max_diff_px);
        setIfUnset(s.p1, tuned.p1);
        setIfUnset(s.p2, tuned.p2);
        setIfUnset(s.census_width, tuned.census_width);
        setIfUnset(s.census_height, tuned.census_height);
        setIfUnset(s.paths, tuned.paths);
        setIfUnset(s.p2_gradient_scale, tuned.p2_gradient_scale);
        setIfUnset(s.threads, automaticMatcherThreads());
        return s;
    }
    setIfUnset(s.uniqueness_ratio, 10);
    setIfUnset(s.speckle_window_px, 100);
    setIfUnset(s.speckle_range_px, 2);
    setIfUnset(s.lr_max_diff_px, 1);
    // The automatic penalties grow with the block's area. A block beyond every matcher's
    // range (StereoBM's 255 px at most), which the checks refuse after this, must not
    // overflow them first: 2113092847 px did (found by fuzz_config).
    const int side = std::clamp(s.block_size, 0, 255);
    const int area = side * side;
    setIfUnset(s.p1, 8 * area);
    setIfUnset(s.p2, 32 * area);
    return s;
}

} // namespace stereod
