#pragma once
// A point or a direction in three dimensions (x, y, z; or roll, pitch, yaw), without
// OpenCV: what the zones, the camera's pose and their JSON carry. The pipeline computes
// with cv::Vec3d and converts in one place (pipeline/cv_conversions.hpp).
//
// Plain values. Units: as the field holding one says (metres, degrees).

#include <array>

namespace stereod {

using Vec3 = std::array<double, 3>;

} // namespace stereod
