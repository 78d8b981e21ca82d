#include "ros2/range_reading.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stereod::ros2 {

double regionFieldOfViewRad(const RectifiedGeometry& geometry, const RegionOfInterest& roi)
{
    if (geometry.focal_px <= 0.0)
        return 0.0;
    const double width_px = geometry.image_size.width;
    const double left_px = roi.x * width_px - geometry.cx_px;
    const double right_px = (roi.x + roi.width) * width_px - geometry.cx_px;
    return std::atan(right_px / geometry.focal_px) - std::atan(left_px / geometry.focal_px);
}

RangeValues rangeFromReading(const Reading& reading, const NearestSettings& nearest,
                             const RectifiedGeometry& geometry)
{
    RangeValues values;
    values.field_of_view = static_cast<float>(regionFieldOfViewRad(geometry, nearest.roi));
    // What the service can report lies beyond both the configured minimum and the
    // closest depth the disparity range reaches.
    values.min_range = static_cast<float>(std::max(nearest.min_depth_m, reading.closest_m));
    values.max_range = static_cast<float>(nearest.max_depth_m);
    if (reading.valid) {
        values.range = static_cast<float>(reading.distance_m);
    } else if (reading.reason == NoReadingReason::NearerThanRange) {
        values.range = -std::numeric_limits<float>::infinity();
    } else if (reading.reason == NoReadingReason::NothingInRange) {
        values.range = std::numeric_limits<float>::infinity();
    } else {
        values.range = std::numeric_limits<float>::quiet_NaN();
    }
    return values;
}

} // namespace stereod::ros2
