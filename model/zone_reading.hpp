#pragma once
// What the keep-out zones say for a frame (pipeline/zones.hpp makes it), and where the
// camera sits on the robot: written as JSON for the socket's `zones` request and events,
// drawn by the live view, and published as the camera's frames on ROS 2.
//
// Frames (REP 103 / REP 105): the robot's base frame has x forward, y left, z up, metres.
//
// Plain values; zoneStateName() is pure (any thread). Units in the field names.

#include <cstdint>
#include <string>

#include "base/name_table.hpp"
#include "model/vec3.hpp"

namespace stereod {

// Where the camera sits on the robot.
struct CameraPose {
    Vec3 translation_m{0.0, 0.0, 0.0}; // camera origin in the base frame
    Vec3 rpy_deg{0.0, 0.0, 0.0};       // roll, pitch, yaw of the camera body (x forward)
};

enum class ZoneState { Clear, Occupied, Unknown };

inline constexpr NameTable<ZoneState, 3> kZoneStates{{{
    {ZoneState::Clear, "clear"},
    {ZoneState::Occupied, "occupied"},
    {ZoneState::Unknown, "unknown"},
}}};
static_assert(kZoneStates.wellFormed());

// "clear", "occupied", "unknown".
const char* zoneStateName(ZoneState state) noexcept;

struct ZoneReading {
    std::string name;
    Vec3 min_m{0.0, 0.0, 0.0}; // the zone's box, base frame (from its settings)
    Vec3 max_m{0.0, 0.0, 0.0};
    ZoneState state = ZoneState::Unknown;
    std::string reason;                  // for unknown: "not_visible", "no_frame"
    int points = 0;                      // depth points inside this frame (pixel_step counted once)
    double nearest_m = 0.0;              // distance of the nearest point from the base origin
    Vec3 nearest_point_m{0.0, 0.0, 0.0}; // where it is, base frame (see nearest_percentile)
    double visible_fraction = 0.0; // share of the zone's volume in sight (seen empty or filled)
    bool occupied_now = false;     // this frame alone, before hysteresis
    int64_t stamp_ns = 0;          // capture time of the pair
    uint64_t frame = 0;
};

} // namespace stereod
