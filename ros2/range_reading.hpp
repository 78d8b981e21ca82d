#pragma once
// The nearest-object reading as a sensor_msgs/msg/Range, whose own definition fits ours:
// `range` is the distance when the reading is valid, -Inf when something is nearer than
// min_range (our nearer_than_range), +Inf when nothing is in range (nothing_in_range),
// and NaN for every other "no reading"; min_range and max_range are the depths the
// reading can report; field_of_view is the region of interest's horizontal angle.
//
// Reentrant: pure functions. Units: metres and radians (as the message has them).

#include "model/reading.hpp"
#include "model/rectified_geometry.hpp"
#include "pipeline/nearest_settings.hpp"

namespace stereod::ros2 {

// The fields of sensor_msgs/msg/Range, as floats like the message.
struct RangeValues {
    float field_of_view = 0.0f; // rad
    float min_range = 0.0f;     // m
    float max_range = 0.0f;     // m
    float range = 0.0f;         // m, or -Inf / +Inf / NaN as above
};

// The horizontal angle the region of interest spans in the rectified left image, rad.
double regionFieldOfViewRad(const RectifiedGeometry& geometry, const RegionOfInterest& roi);

// The Range of `reading`. min_range is the nearer of the configured minimum depth and the
// closest depth the matcher measures (reading.closest_m, when known); max_range the
// configured maximum.
RangeValues rangeFromReading(const Reading& reading, const NearestSettings& nearest,
                             const RectifiedGeometry& geometry);

} // namespace stereod::ros2
