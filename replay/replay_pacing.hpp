#pragma once
// How a replay delivers its pairs: one enum for the replay source and the configuration.

namespace stereod {

enum class ReplayPacing {
    Paced,    // at the recorded time spacing, like real cameras
    Lockstep, // as fast as the consumer takes pairs; nothing dropped, repeatable
};

} // namespace stereod
