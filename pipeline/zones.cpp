#include "pipeline/zones.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "pipeline/cv_conversions.hpp"

namespace stereod {
namespace {

[[noreturn]] void invalid(const std::string& key, const std::string& problem)
{
    throw std::invalid_argument(key + ": " + problem);
}

cv::Matx33d rotationX(double a)
{
    const double c = std::cos(a), s = std::sin(a);
    return {1, 0, 0, 0, c, -s, 0, s, c};
}

cv::Matx33d rotationY(double a)
{
    const double c = std::cos(a), s = std::sin(a);
    return {c, 0, s, 0, 1, 0, -s, 0, c};
}

cv::Matx33d rotationZ(double a)
{
    const double c = std::cos(a), s = std::sin(a);
    return {c, -s, 0, s, c, 0, 0, 0, 1};
}

bool inside(const cv::Vec3d& p, const ZoneSettings& zone)
{
    for (int i = 0; i < 3; ++i)
        if (p[i] < zone.min_m[i] || p[i] > zone.max_m[i])
            return false;
    return true;
}

bool usableDepth(float z)
{
    return z > 0.0f && std::isfinite(z);
}

} // namespace

void validateZonesSettings(const ZonesSettings& s)
{
    const auto within = [](double value, double limit) {
        return std::isfinite(value) && std::abs(value) <= limit;
    };
    for (int i = 0; i < 3; ++i) {
        if (!within(s.camera_pose.translation_m[i], kMaxZoneCoordinateM))
            invalid("robot.camera_pose.translation_m",
                    "must be finite and within 1000 m of the base origin");
        if (!within(s.camera_pose.rpy_deg[i], 360.0))
            invalid("robot.camera_pose.rpy_deg", "must be finite angles within +-360 degrees");
    }
    if (s.zones.size() > kMaxZones)
        invalid("zones", std::to_string(s.zones.size()) + " zones, more than the " +
                             std::to_string(kMaxZones) + " a frame can afford");
    if (!(s.min_visible_fraction >= 0.0 && s.min_visible_fraction <= 1.0))
        invalid("zones_min_visible_fraction", "must be within 0..1");
    if (s.pixel_step < 1 || s.pixel_step > 16)
        invalid("zones_pixel_step", "must be within 1..16");
    if (s.visibility_samples < 2 || s.visibility_samples > 32)
        invalid("zones_visibility_samples", "must be within 2..32");
    if (!(s.nearest_percentile >= 0.0 && s.nearest_percentile <= 100.0))
        invalid("zones_nearest_percentile", "must be within 0..100");
    for (size_t z = 0; z < s.zones.size(); ++z) {
        const ZoneSettings& zone = s.zones[z];
        const std::string key = "zones[" + std::to_string(z) + "]";
        if (zone.name.empty())
            invalid(key + ".name", "must not be empty");
        for (size_t other = 0; other < z; ++other)
            if (s.zones[other].name == zone.name)
                invalid(key + ".name", "\"" + zone.name + "\" is used twice");
        for (int i = 0; i < 3; ++i)
            if (!(within(zone.min_m[i], kMaxZoneCoordinateM) &&
                  within(zone.max_m[i], kMaxZoneCoordinateM) && zone.min_m[i] < zone.max_m[i]))
                invalid(key + ".max", "each coordinate must be finite, within 1000 m of the base "
                                      "origin and greater than min's");
        if (zone.min_points < 1)
            invalid(key + ".min_points", "must be >= 1");
        if (zone.enter_frames < 1 || zone.leave_frames < 1)
            invalid(key + ".enter_frames", "enter_frames and leave_frames must be >= 1");
    }
}

cv::Matx33d opticalToBaseRotation(const CameraPose& pose)
{
    // Optical (x right, y down, z forward) to the camera body (x forward, y left, z up).
    const cv::Matx33d optical_to_body(0, 0, 1, -1, 0, 0, 0, -1, 0);
    constexpr double kRadians = CV_PI / 180.0;
    const cv::Matx33d body_to_base = rotationZ(pose.rpy_deg[2] * kRadians) *
                                     rotationY(pose.rpy_deg[1] * kRadians) *
                                     rotationX(pose.rpy_deg[0] * kRadians);
    return body_to_base * optical_to_body;
}

ZoneMonitor::ZoneMonitor(const ZonesSettings& settings)
{
    reconfigure(settings);
}

void ZoneMonitor::reconfigure(const ZonesSettings& settings)
{
    validateZonesSettings(settings);
    std::vector<Track> tracks(settings.zones.size());
    std::vector<ZoneReading> readings(settings.zones.size());
    for (size_t z = 0; z < settings.zones.size(); ++z) {
        readings[z].name = settings.zones[z].name;
        readings[z].reason = "no_frame";
        for (size_t old = 0; old < settings_.zones.size(); ++old)
            if (settings_.zones[old].name == settings.zones[z].name) {
                tracks[z] = tracks_[old];
                readings[z] = readings_[old];
            }
        readings[z].min_m = settings.zones[z].min_m;
        readings[z].max_m = settings.zones[z].max_m;
    }
    settings_ = settings;
    rotation_ = opticalToBaseRotation(settings.camera_pose);
    tracks_ = std::move(tracks);
    readings_ = std::move(readings);
    inside_.resize(settings_.zones.size());
}

double ZoneMonitor::visibleFraction(const ZoneSettings& zone, const cv::Mat& depth_m,
                                    const RectifiedGeometry& g, double closest_depth_m) const
{
    const int n = settings_.visibility_samples;
    const cv::Matx33d base_to_optical = rotation_.t();
    const cv::Vec3d t = toCv(settings_.camera_pose.translation_m);
    int visible = 0;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            for (int k = 0; k < n; ++k) {
                const cv::Vec3d fraction((i + 0.5) / n, (j + 0.5) / n, (k + 0.5) / n);
                cv::Vec3d p_base;
                for (int a = 0; a < 3; ++a)
                    p_base[a] = zone.min_m[a] + fraction[a] * (zone.max_m[a] - zone.min_m[a]);
                const cv::Vec3d p = base_to_optical * (p_base - t);
                if (!(p[2] > closest_depth_m))
                    continue; // behind the camera, or nearer than the range sees
                const int u = static_cast<int>(std::lround(g.focal_px * p[0] / p[2] + g.cx_px));
                const int v = static_cast<int>(std::lround(g.focal_px * p[1] / p[2] + g.cy_px));
                if (u < 0 || v < 0 || u >= depth_m.cols || v >= depth_m.rows)
                    continue; // outside the field of view
                const float z = depth_m.at<float>(v, u);
                // No depth along that ray says nothing of what is there.
                if (!usableDepth(z))
                    continue;
                // Seen through: the ray's surface lies beyond the sample (a little slack
                // for the depth's own error), so the sample is seen empty.
                const double slack = std::max(0.05, 0.02 * p[2]);
                if (z >= p[2] - slack) {
                    ++visible;
                    continue;
                }
                // A surface nearer than the sample: inside the zone it is what fills the
                // zone there, seen; outside (in front of the zone) it hides the sample.
                const cv::Vec3d surface_optical((u - g.cx_px) * z / g.focal_px,
                                                (v - g.cy_px) * z / g.focal_px, z);
                if (inside(rotation_ * surface_optical + t, zone))
                    ++visible;
            }
    return static_cast<double>(visible) / (static_cast<double>(n) * n * n);
}

const std::vector<ZoneReading>& ZoneMonitor::markUnknown(const char* reason, int64_t stamp_ns,
                                                         uint64_t frame)
{
    for (ZoneReading& zone : readings_) {
        zone.state = ZoneState::Unknown;
        zone.reason = reason;
        zone.points = 0;
        zone.nearest_m = 0.0;
        zone.nearest_point_m = {0.0, 0.0, 0.0};
        zone.visible_fraction = 0.0;
        zone.occupied_now = false;
        zone.stamp_ns = stamp_ns;
        zone.frame = frame;
    }
    return readings_;
}

const std::vector<ZoneReading>& ZoneMonitor::update(const cv::Mat& depth_m,
                                                    const RectifiedGeometry& g,
                                                    double closest_depth_m, int64_t stamp_ns,
                                                    uint64_t frame)
{
    CV_Assert(depth_m.type() == CV_32FC1);
    const size_t zones = settings_.zones.size();
    for (ZoneReading& r : readings_) {
        r.points = 0;
        r.nearest_m = 0.0;
        r.nearest_point_m = {0.0, 0.0, 0.0};
        r.stamp_ns = stamp_ns;
        r.frame = frame;
    }
    for (std::vector<Point>& points : inside_)
        points.clear();
    const int step = settings_.pixel_step;
    const cv::Vec3d t = toCv(settings_.camera_pose.translation_m);
    for (int v = 0; v < depth_m.rows && zones > 0; v += step) {
        const float* row = depth_m.ptr<float>(v);
        for (int u = 0; u < depth_m.cols; u += step) {
            const float z = row[u];
            if (!usableDepth(z))
                continue;
            const cv::Vec3d optical((u - g.cx_px) * z / g.focal_px, (v - g.cy_px) * z / g.focal_px,
                                    z);
            const cv::Vec3d p = rotation_ * optical + t;
            for (size_t i = 0; i < zones; ++i) {
                if (!inside(p, settings_.zones[i]))
                    continue;
                ++readings_[i].points;
                inside_[i].push_back({cv::norm(p), p});
            }
        }
    }
    for (size_t i = 0; i < zones; ++i) {
        const ZoneSettings& zone = settings_.zones[i];
        ZoneReading& r = readings_[i];
        Track& track = tracks_[i];
        r.occupied_now = r.points >= zone.min_points;
        if (r.occupied_now) {
            ++track.occupied_run;
            track.free_run = 0;
            if (track.occupied_run >= zone.enter_frames)
                track.occupied = true;
        } else {
            ++track.free_run;
            track.occupied_run = 0;
            if (track.free_run >= zone.leave_frames)
                track.occupied = false;
        }
        r.visible_fraction = visibleFraction(zone, depth_m, g, closest_depth_m);
        std::vector<Point>& points = inside_[i];
        if (!points.empty()) {
            constexpr size_t kAtLeast = 4; // the 5th nearest point, 0-based
            const size_t rank = std::min(
                points.size() - 1,
                std::max(kAtLeast, static_cast<size_t>(settings_.nearest_percentile / 100.0 *
                                                       static_cast<double>(points.size()))));
            std::nth_element(
                points.begin(), points.begin() + static_cast<std::ptrdiff_t>(rank), points.end(),
                [](const Point& a, const Point& b) { return a.distance_m < b.distance_m; });
            r.nearest_m = points[rank].distance_m;
            r.nearest_point_m = toVec3(points[rank].base_m);
        }
        if (track.occupied) {
            r.state = ZoneState::Occupied;
            r.reason.clear();
        } else if (r.visible_fraction < settings_.min_visible_fraction) {
            r.state = ZoneState::Unknown;
            r.reason = "not_visible";
        } else {
            r.state = ZoneState::Clear;
            r.reason.clear();
        }
    }
    return readings_;
}

} // namespace stereod
