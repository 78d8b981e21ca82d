#pragma once
// Keep-out zones in the robot's own frame: "is anything inside the space I am about to
// drive through?", and "can I see that space at all?".
//
// Frames (REP 103 / REP 105): the robot's base frame has x forward, y left, z up, metres;
// the camera's pose in it is `robot.camera_pose` (translation, and roll/pitch/yaw of the
// camera body, whose x axis looks forward along the optical axis). Depth comes in the
// optical frame of the rectified left camera (x right, y down, z forward).
//
// For each zone (an axis-aligned box in the base frame) and frame: the depth points inside
// it, the nearest one's distance from the base origin and where it is, and how much of the
// zone's volume the camera can see: the part inside the field of view, beyond the closest
// depth the disparity range reaches, and either seen empty (the ray's surface lies beyond
// it) or behind a surface inside the zone (what fills the zone there); not the part
// hidden behind a surface in front of the zone, or behind a pixel with no depth, about
// which nothing is known. Occupied or clear with hysteresis
// over frames; below `min_visible_fraction` a zone with no points in it is `unknown`,
// never `clear`: an empty answer from a blind camera is the most dangerous reading.
//
// Thread-bound: a ZoneMonitor keeps each zone's hysteresis and its scratch buffers.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/matx.hpp>

#include "model/vec3.hpp"
#include "model/zone_reading.hpp"
#include "pipeline/calibration.hpp"

namespace stereod {

struct ZoneSettings {
    std::string name;
    Vec3 min_m{0.0, 0.0, 0.0}; // box corners in the base frame, min < max
    Vec3 max_m{0.0, 0.0, 0.0};
    int min_points = 50;  // depth points inside that make it occupied
    int enter_frames = 2; // consecutive occupied frames to turn occupied
    int leave_frames = 3; // consecutive free frames to turn clear again
};

struct ZonesSettings {
    CameraPose camera_pose;
    std::vector<ZoneSettings> zones;
    // Below this share of a zone's volume in sight, a zone with no points is unknown.
    double min_visible_fraction = 0.5;
    // Depth pixels used: every `pixel_step`-th in both directions (1: all).
    int pixel_step = 2;
    // Volume samples per zone side for the visibility estimate (n^3 samples).
    int visibility_samples = 10;
    // The nearest point reported is this percentile of the distances inside the zone (at
    // least the 5th nearest point): a few wrong pixels cannot move it.
    double nearest_percentile = 1.0;
};

// Zones at most: each costs a test per depth point, a sort of the points inside it and a
// volume of samples per frame (measured at 718x496, boxes of about 4000 points: 1.3 ms of
// CPU a frame for one, 4.5 ms for 16; 5000 took a 10 fps service down to 4).
inline constexpr std::size_t kMaxZones = 16;
// Coordinates at most this far from the base origin, m: a camera and the space a robot
// drives through lie within it, and points that far apart keep their distances finite.
inline constexpr double kMaxZoneCoordinateM = 1000.0;

// Throws std::invalid_argument naming the setting ("zones[1].max: ...") when unusable:
// more than kMaxZones zones, a coordinate beyond kMaxZoneCoordinateM, an angle beyond
// +-360 degrees, or anything not finite.
void validateZonesSettings(const ZonesSettings& settings);

// The rotation and translation from the rectified left camera's optical frame to the base
// frame: p_base = R * p_optical + t.
cv::Matx33d opticalToBaseRotation(const CameraPose& pose);

class ZoneMonitor {
  public:
    explicit ZoneMonitor(const ZonesSettings& settings);

    // depth_m: CV_32FC1, metres, invalid 0/NaN/inf; geometry: the rectified camera;
    // closest_depth_m: the nearest depth the disparity range can see (nearer is blind).
    const std::vector<ZoneReading>& update(const cv::Mat& depth_m,
                                           const RectifiedGeometry& geometry,
                                           double closest_depth_m, int64_t stamp_ns,
                                           uint64_t frame);

    // A pair whose depth is not to be trusted (out of sync, a bad frame): every zone is
    // unknown for it with `reason`, and no zone's hysteresis moves.
    const std::vector<ZoneReading>& markUnknown(const char* reason, int64_t stamp_ns,
                                                uint64_t frame);

    // New zones or pose, applied live: the hysteresis of zones whose name stays is kept.
    void reconfigure(const ZonesSettings& settings);

    const std::vector<ZoneReading>& readings() const { return readings_; }
    const ZonesSettings& settings() const { return settings_; }

  private:
    struct Track {
        int occupied_run = 0;
        int free_run = 0;
        bool occupied = false;
    };
    double visibleFraction(const ZoneSettings& zone, const cv::Mat& depth_m,
                           const RectifiedGeometry& geometry, double closest_depth_m) const;

    struct Point {
        double distance_m;
        cv::Vec3d base_m;
    };
    ZonesSettings settings_;
    cv::Matx33d rotation_; // optical -> base
    std::vector<Track> tracks_;
    std::vector<std::vector<Point>> inside_; // per zone, this frame's points; capacity kept
    std::vector<ZoneReading> readings_;
};

} // namespace stereod
