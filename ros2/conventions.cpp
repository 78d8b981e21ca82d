#include "ros2/conventions.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <opencv2/imgproc.hpp>

namespace stereod::ros2 {

void copyTrustedDepth(const DepthResult& result, bool depth_valid, cv::Mat& out)
{
    if (depth_valid) {
        result.depth_m.copyTo(out);
    } else {
        out.create(result.left_rectified.size(), CV_32FC1);
        out.setTo(0);
    }
}

void depthWithNan(const cv::Mat& depth_m, std::vector<float>& out)
{
    out.resize(depth_m.total());
    const auto* depth = depth_m.ptr<float>();
    for (std::size_t i = 0; i < out.size(); ++i)
        out[i] = depth[i] > 0.0f ? depth[i] : std::nanf("");
}

void disparityForRos(const cv::Mat& disparity, float min_disparity, std::vector<float>& out)
{
    out.resize(disparity.total());
    const auto* d = disparity.ptr<float>();
    for (std::size_t i = 0; i < out.size(); ++i)
        out[i] = std::isfinite(d[i]) ? d[i] : min_disparity - 1.0f;
}

const char* leftImageForRos(const DepthResult& result, cv::Mat& out)
{
    if (result.left_rectified_colour.empty()) {
        result.left_rectified.copyTo(out);
        return "mono8";
    }
    cv::cvtColor(result.left_rectified_colour, out, cv::COLOR_BGR2RGB);
    return "rgb8";
}

float packedRgb(CloudColour colour) noexcept
{
    const uint32_t bits = (uint32_t{colour.r} << 16) | (uint32_t{colour.g} << 8) | colour.b;
    float packed = 0.0f;
    std::memcpy(&packed, &bits, sizeof packed);
    return packed;
}

void subsampleCloud(const DepthResult& result, int step, std::vector<CloudPoint>& points,
                    std::vector<CloudColour>& colours)
{
    const auto stride = static_cast<std::size_t>(std::max(1, step));
    const bool coloured = result.cloud_colour.size() == result.cloud.size();
    points.clear();
    colours.clear();
    for (std::size_t i = 0; i < result.cloud.size(); i += stride) {
        points.push_back(result.cloud[i]);
        if (coloured)
            colours.push_back(result.cloud_colour[i]);
    }
}

void xyziRgbCloud(const std::vector<CloudPoint>& points, const std::vector<CloudColour>& colours,
                  std::vector<float>& out)
{
    const std::size_t count = std::min(points.size(), colours.size());
    out.resize(5 * count);
    for (std::size_t i = 0; i < count; ++i) {
        float* point = out.data() + 5 * i;
        point[0] = points[i].x;
        point[1] = points[i].y;
        point[2] = points[i].z;
        point[3] = points[i].intensity;
        point[4] = packedRgb(colours[i]);
    }
}

CameraInfo rectifiedCameraInfo(const RectifiedGeometry& g, bool right, int64_t stamp_ns)
{
    CameraInfo info;
    info.header = {Time::fromNs(stamp_ns), right ? kRightOpticalFrame : kLeftOpticalFrame};
    info.width = static_cast<uint32_t>(g.image_size.width);
    info.height = static_cast<uint32_t>(g.image_size.height);
    info.distortion_model = "plumb_bob";
    info.d = {0, 0, 0, 0, 0}; // rectified: no distortion left
    const double cx = right ? g.cx_px + g.doffs_px : g.cx_px;
    info.k = {g.focal_px, 0, cx, 0, g.focal_px, g.cy_px, 0, 0, 1};
    info.r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    info.p = {g.focal_px, 0,          cx,      right ? -g.focal_px * g.baseline_m : 0.0,
              0,          g.focal_px, g.cy_px, 0,
              0,          0,          1,       0};
    return info;
}

} // namespace stereod::ros2
