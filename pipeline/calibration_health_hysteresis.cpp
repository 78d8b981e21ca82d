#include "pipeline/calibration_health_hysteresis.hpp"

namespace stereod {
namespace {

// How bad a verdict is: ok < degraded < failed. Unknown is no verdict and never compared.
int severity(HealthState state)
{
    switch (state) {
    case HealthState::Ok:
        return 0;
    case HealthState::Degraded:
        return 1;
    case HealthState::Failed:
        return 2;
    case HealthState::Unknown:
        break;
    }
    return -1;
}

HealthSettings lowered(HealthSettings s, double fraction)
{
    s.ok_row_error_px *= fraction;
    s.failed_offset_px *= fraction;
    s.failed_row_error_px *= fraction;
    s.degraded_roll_deg *= fraction;
    s.failed_roll_deg *= fraction;
    return s;
}

} // namespace

HealthHysteresis::HealthHysteresis(const HealthSettings& verdict,
                                   const HealthHysteresisSettings& settings)
    : leave_(lowered(verdict, settings.leave_fraction)), settings_(settings)
{
}

void HealthHysteresis::reset()
{
    become(HealthState::Unknown, "");
}

void HealthHysteresis::become(HealthState state, const std::string& reason)
{
    state_ = state;
    reason_ = state == HealthState::Ok ? std::string() : reason;
    worse_in_a_row_ = 0;
    better_in_a_row_ = 0;
}

bool HealthHysteresis::update(const HealthMeasurement& check)
{
    if (check.state == HealthState::Unknown)
        return false;
    if (state_ == HealthState::Unknown) {
        become(check.state, check.reason);
        return true;
    }
    // The same figures judged by the lower thresholds: what the check says a better state
    // would need.
    HealthMeasurement strict = check;
    classifyHealth(strict, leave_);

    if (severity(check.state) > severity(state_)) {
        // The least bad of the checks in the row (the newest of equals) is where it goes.
        if (worse_in_a_row_ == 0 || severity(check.state) <= severity(worse_to_)) {
            worse_to_ = check.state;
            worse_reason_ = check.reason;
        }
        ++worse_in_a_row_;
        better_in_a_row_ = 0;
        if (worse_in_a_row_ < settings_.enter_checks)
            return false;
        become(worse_to_, worse_reason_);
        return true;
    }
    if (severity(strict.state) < severity(state_)) {
        // The worst of the checks in the row (the newest of equals) is where it goes.
        if (better_in_a_row_ == 0 || severity(strict.state) >= severity(better_to_)) {
            better_to_ = strict.state;
            better_reason_ = strict.reason;
        }
        ++better_in_a_row_;
        worse_in_a_row_ = 0;
        if (better_in_a_row_ < settings_.leave_checks)
            return false;
        become(better_to_, better_reason_);
        return true;
    }
    // The check bears the state out.
    worse_in_a_row_ = 0;
    better_in_a_row_ = 0;
    if (check.state == state_)
        reason_ = check.reason;
    return false;
}

} // namespace stereod
