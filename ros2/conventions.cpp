#include "ros2/conventions.hpp"

#include <cmath>

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
