#pragma once
// How a replay delivers its pairs: one enum for the replay source and the configuration.

#include "base/name_table.hpp"

namespace stereod {

enum class ReplayPacing {
    Paced,    // at the recorded time spacing, like real cameras
    Lockstep, // as fast as the consumer takes pairs; nothing dropped, repeatable
};

// The names of source.replay.pacing (and of the replay's log line).
inline constexpr NameTable<ReplayPacing, 2> kReplayPacings{{{
    {ReplayPacing::Paced, "paced"},
    {ReplayPacing::Lockstep, "lockstep"},
}}};
static_assert(kReplayPacings.wellFormed());

} // namespace stereod
