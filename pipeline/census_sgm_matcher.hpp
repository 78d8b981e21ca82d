#pragma once
// Our census + semi-global matcher (pipeline/sgm) behind the Matcher interface: the
// service's default, with its extended range and near-field probe (pyramid_sgm.hpp). The
// core is sized for one image size; it is set up on the first pair of a size (the only
// allocation) and again after configure().

#include <memory>

#include "pipeline/matcher.hpp"
#include "pipeline/sgm/census_sgm.hpp"
#include "pipeline/sgm/pyramid_sgm.hpp"

namespace stereod {

// The core's settings for these matcher settings and range (image size left 0x0):
// the settings that are unset take their effective values (effectiveMatcherSettings).
sgm::CensusSgmSettings censusSgmSettings(const MatcherSettings& settings,
                                         const DisparityRange& range);

// The same with the levels around it: the extended range as configured, and the near-field
// probe.
sgm::PyramidSgmSettings pyramidSgmSettings(const MatcherSettings& settings,
                                           const DisparityRange& range);

// Throws SettingsError naming the MatcherSettings field that cannot work.
void validateCensusSgm(const MatcherSettings& settings);

std::unique_ptr<Matcher> makeCensusSgmMatcher(const MatcherSettings& settings,
                                              const DisparityRange& range);

// The cores this process may run on (its CPU affinity), at least 1.
int availableCores();

} // namespace stereod
