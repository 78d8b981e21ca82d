// The state a service reports from its checks one after the other: it changes only when
// several checks in a row say so, recovers only below lower limits, and a check without
// a verdict changes nothing. One table of check sequences and the states they lead to.

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/calibration_health.hpp"
#include "pipeline/calibration_health_hysteresis.hpp"

namespace stereod {
namespace {

// A check as the checker reports it: the model's largest row error and roll, classified
// with the default verdict settings (ok up to 0.7 px and under 0.2 deg, failed from 2 px
// at the centre). "-" is a check with too few matches.
HealthMeasurement check(const std::string& what)
{
    HealthMeasurement m;
    m.matches = 100;
    if (what == "-") {
        m.matches = 3;
    } else if (what == "ok") {
        m.model.max_row_error_px = 0.2;
    } else if (what == "ok-ish") { // ok, but above the lower limit (0.7 x 0.7 px)
        m.model.max_row_error_px = 0.6;
    } else if (what == "rows") {
        m.model.max_row_error_px = 1.1;
    } else if (what == "roll") {
        m.model.max_row_error_px = 0.5;
        m.model.roll_deg = 0.3;
    } else if (what == "failed") {
        m.model.offset_px = 2.5;
        m.model.max_row_error_px = 2.6;
    }
    classifyHealth(m, HealthSettings{});
    return m;
}

struct Case {
    const char* name;
    std::vector<std::string> checks;
    HealthState state;
    const char* reason;
    int changes; // after the first verdict
};

const Case kCases[] = {
    {"no check with a verdict yet", {"-", "-"}, HealthState::Unknown, "", 0},
    {"the first verdict sets the state", {"-", "rows"}, HealthState::Degraded, "row_offset", 0},
    {"two bad checks are noise", {"ok", "rows", "roll", "ok"}, HealthState::Ok, "", 0},
    {"three bad checks in a row",
     {"ok", "rows", "roll", "rows"},
     HealthState::Degraded,
     "row_offset",
     1},
    {"a check without a verdict does not break the row",
     {"ok", "rows", "-", "rows", "-", "roll"},
     HealthState::Degraded,
     "roll",
     1},
    {"an ok check breaks it", {"ok", "rows", "rows", "ok", "rows", "rows"}, HealthState::Ok, "", 0},
    {"to the least bad of the three",
     {"ok", "failed", "rows", "failed"},
     HealthState::Degraded,
     "row_offset",
     1},
    {"three failed checks",
     {"ok", "failed", "failed", "failed"},
     HealthState::Failed,
     "row_offset",
     1},
    {"recovery needs five checks well below the limits",
     {"rows", "ok", "ok", "ok", "ok"},
     HealthState::Degraded,
     "row_offset",
     0},
    {"five good checks", {"rows", "ok", "ok", "ok", "ok", "ok"}, HealthState::Ok, "", 1},
    {"checks just under the limit are not good enough",
     {"rows", "ok-ish", "ok-ish", "ok-ish", "ok-ish", "ok-ish", "ok-ish"},
     HealthState::Degraded,
     "row_offset",
     0},
    {"failed recovers to what the checks say",
     {"failed", "rows", "ok", "ok", "rows", "ok"},
     HealthState::Degraded,
     "row_offset",
     1},
    {"a bad check keeps a degraded state",
     {"rows", "ok", "ok", "rows", "ok", "ok", "ok", "ok"},
     HealthState::Degraded,
     "row_offset",
     0},
};

TEST(HealthHysteresis, StateFollowsTheChecksAsTheTableSays)
{
    for (const Case& c : kCases) {
        HealthHysteresis hysteresis;
        int changes = 0;
        bool had_state = false;
        for (const std::string& what : c.checks) {
            const bool changed = hysteresis.update(check(what));
            changes += changed && had_state;
            had_state = hysteresis.state() != HealthState::Unknown;
        }
        EXPECT_EQ(hysteresis.state(), c.state) << c.name;
        EXPECT_EQ(hysteresis.reason(), c.reason) << c.name;
        EXPECT_EQ(changes, c.changes) << c.name;
    }
}

TEST(HealthHysteresis, ResetForgetsTheState)
{
    HealthHysteresis hysteresis;
    hysteresis.update(check("rows"));
    ASSERT_EQ(hysteresis.state(), HealthState::Degraded);
    hysteresis.reset();
    EXPECT_EQ(hysteresis.state(), HealthState::Unknown);
    EXPECT_TRUE(hysteresis.update(check("ok")));
    EXPECT_EQ(hysteresis.state(), HealthState::Ok);
}

} // namespace
} // namespace stereod
