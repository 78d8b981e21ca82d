#include "pipeline/triangulation.hpp"

#include <bit>
#include <cstdint>
#include <limits>

namespace stereod {

void disparityToDepth(const cv::Mat& disparity_px, const RectifiedGeometry& geometry,
                      cv::Mat& depth_m)
{
    CV_Assert(disparity_px.type() == CV_32FC1);
    depth_m.create(disparity_px.size(), CV_32FC1);
    // Single precision, and the validity test a select rather than a branch: the division
    // per pixel is the stage's whole cost, and a branch on validity (a pattern the scene
    // decides) kept the loop from being vector code. One thread: it is a fraction of a
    // millisecond at 640x480, less than handing rows to a pool and back.
    constexpr float kInfinity = std::numeric_limits<float>::infinity();
    const auto fb = static_cast<float>(geometry.focal_px * geometry.baseline_m);
    const auto doffs = static_cast<float>(geometry.doffs_px);
    for (int y = 0; y < disparity_px.rows; ++y) {
        const float* d = disparity_px.ptr<float>(y);
        float* z = depth_m.ptr<float>(y);
        for (int x = 0; x < disparity_px.cols; ++x) {
            const float denominator = d[x] + doffs;
            // +inf and NaN fail the test too: both end as 0 (invalid). The division is made
            // for every pixel and the invalid ones masked to +0 by their bits.
            const bool valid = (denominator > 0.0f) & (denominator < kInfinity);
            const uint32_t keep = 0u - static_cast<uint32_t>(valid);
            z[x] = std::bit_cast<float>(std::bit_cast<uint32_t>(fb / denominator) & keep);
        }
    }
}

void clearDepthBeyond(cv::Mat& depth_m, float max_depth_m)
{
    CV_Assert(depth_m.type() == CV_32FC1);
    // A select, not a branch, as in disparityToDepth(): vector code whatever the scene.
    for (int y = 0; y < depth_m.rows; ++y) {
        float* z = depth_m.ptr<float>(y);
        for (int x = 0; x < depth_m.cols; ++x)
            z[x] = z[x] <= max_depth_m ? z[x] : 0.0f;
    }
}

void buildPointCloud(const cv::Mat& depth_m, const cv::Mat& left_rectified,
                     const RectifiedGeometry& geometry, std::vector<CloudPoint>& cloud)
{
    CV_Assert(depth_m.type() == CV_32FC1 && left_rectified.type() == CV_8UC1 &&
              depth_m.size() == left_rectified.size());
    cloud.clear();
    cloud.reserve(depth_m.total());
    const float inv_f = static_cast<float>(1.0 / geometry.focal_px);
    const float cx = static_cast<float>(geometry.cx_px);
    const float cy = static_cast<float>(geometry.cy_px);
    for (int v = 0; v < depth_m.rows; ++v) {
        const float* z = depth_m.ptr<float>(v);
        const uint8_t* grey = left_rectified.ptr<uint8_t>(v);
        const float row_factor = (static_cast<float>(v) - cy) * inv_f;
        for (int u = 0; u < depth_m.cols; ++u) {
            if (!(z[u] > 0.0f))
                continue;
            cloud.push_back(CloudPoint{(static_cast<float>(u) - cx) * inv_f * z[u],
                                       row_factor * z[u], z[u], static_cast<float>(grey[u])});
        }
    }
}

} // namespace stereod
