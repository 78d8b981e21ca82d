#pragma once
// The one place that says what each setting a configuration leaves to the matcher
// (std::nullopt in MatcherSettings: `auto`, or the key left out) becomes, per matcher and,
// for census-sgm, per tuning. Pure functions; thread-safe. Units: those of MatcherSettings.

#include "pipeline/matcher_settings.hpp"
#include "pipeline/sgm/census_sgm.hpp"

namespace stereod {

// census-sgm's values for a tuning: natural, the core's defaults (tuned on the 17 real
// scenes of shared/data); planar and patterns, the core's tables for them (census_sgm.hpp).
constexpr const sgm::CensusSgmSettings& censusSgmTuning(MatcherTuning tuning)
{
    switch (tuning) {
    case MatcherTuning::Planar:
        return sgm::kPlanarSceneSettings;
    case MatcherTuning::Patterns:
        return sgm::kPatternSceneSettings;
    case MatcherTuning::Natural:
        break;
    }
    return sgm::kNaturalSceneSettings;
}

// `settings` with every unset setting that applies to its matcher set to the value the
// matcher uses:
// - census-sgm: its tuning's values (censusSgmTuning); threads, the cores available, at
//   most 8.
// - OpenCV's SGBM (every mode) and BM: the values of OpenCV's stereo_match sample
//   (uniqueness 10, speckles 100 px within 2 px, left-right 1 px) and SGBM's recommended
//   penalties P1 = 8 * block_size^2, P2 = 32 * block_size^2; census-sgm's own settings
//   (census window, paths, gradient scale, threads) stay unset: they do not apply.
// num_disparities stays as it is: unset, the calibration and min_depth_m decide it
// (StereoProcessor).
MatcherSettings effectiveMatcherSettings(const MatcherSettings& settings);

// The threads census-sgm matches with when matcher.threads is unset.
int automaticMatcherThreads();

} // namespace stereod
