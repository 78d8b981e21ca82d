#pragma once
// The calibration health a service reports, from its checks one after the other
// (pipeline/calibration_health.hpp): the state changes only when the evidence does.
//  - It gets worse after enter_checks checks in a row that are worse than it (by the
//    verdict's own thresholds), to the least bad of what they said.
//  - It gets better after leave_checks checks in a row that are better than it by lower
//    thresholds (leave_fraction of the verdict's row error and roll limits), to the worst
//    of what they said: a rig at the limit does not go back and forth.
//  - A check without a verdict (too few matches: a blank wall, a dark room) is no
//    evidence either way: it changes nothing, not even the counts in a row.
//  - The first check with a verdict sets the state: before it there is none to keep.
// One check that says otherwise is noise on a single pair (a scene with few features in
// one corner, a periodic pattern); a rig that has moved says so check after check.
//
// Thread-bound: one owner calls update(); no synchronisation of its own.

#include <string>

#include "pipeline/calibration_health.hpp"

namespace stereod {

struct HealthHysteresisSettings {
    int enter_checks = 3; // checks in a row worse than the state before it gets worse
    int leave_checks = 5; // checks in a row better, by the lower thresholds, before it recovers
    double leave_fraction = 0.7; // the lower thresholds: this share of the verdict's limits
};

class HealthHysteresis {
  public:
    explicit HealthHysteresis(const HealthSettings& verdict = {},
                              const HealthHysteresisSettings& settings = {});

    // Takes one check's measurement (as CalibrationHealthChecker classified it with the
    // same verdict settings). True when the state changed.
    bool update(const HealthMeasurement& check);
    // Back to no state (unknown), as before the first check.
    void reset();

    HealthState state() const noexcept { return state_; }
    // The reason of the state: that of the checks that set or confirmed it ("" when ok).
    const std::string& reason() const noexcept { return reason_; }

  private:
    void become(HealthState state, const std::string& reason);

    HealthSettings leave_; // the verdict's thresholds lowered: what a better state needs
    HealthHysteresisSettings settings_;
    HealthState state_ = HealthState::Unknown;
    std::string reason_;
    int worse_in_a_row_ = 0;
    HealthState worse_to_ = HealthState::Unknown; // the least bad of those checks
    std::string worse_reason_;                    // and its reason
    int better_in_a_row_ = 0;
    HealthState better_to_ = HealthState::Unknown; // the worst of those checks
    std::string better_reason_;                    // and its reason
};

} // namespace stereod
