#include "pipeline/triangulation.hpp"

#include <bit>
#include <cstdint>
#include <limits>

#include "pipeline/cloud/cloud_kernels.hpp"
#include "pipeline/row_stripes.hpp"

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

void PointCloudBuilder::build(const cv::Mat& depth_m, const cv::Mat& left_rectified,
                              const RectifiedGeometry& geometry, std::vector<CloudPoint>& cloud)
{
    CV_Assert(depth_m.type() == CV_32FC1 && left_rectified.type() == CV_8UC1 &&
              depth_m.size() == left_rectified.size());
    // Each row's points counted first, then their first indices.
    row_first_.resize(static_cast<size_t>(depth_m.rows) + 1);
    forRowStripes(0, depth_m.rows, [&](int first, int end) {
        for (int v = first; v < end; ++v) {
            const float* z = depth_m.ptr<float>(v);
            size_t count = 0;
            for (int u = 0; u < depth_m.cols; ++u)
                count += z[u] > 0.0f ? 1 : 0;
            row_first_[static_cast<size_t>(v) + 1] = count;
        }
    });
    row_first_[0] = 0;
    for (size_t v = 1; v < row_first_.size(); ++v)
        row_first_[v] += row_first_[v - 1];
    built_from_ = depth_m.data;
    cloud.reserve(depth_m.total());
    // Resizing from the last frame's count initialises only the points it adds.
    cloud.resize(row_first_.back());
    const float inv_f = static_cast<float>(1.0 / geometry.focal_px);
    const float cx = static_cast<float>(geometry.cx_px);
    const float cy = static_cast<float>(geometry.cy_px);
    // (u - cx) / f per column, shared by every row (grown once to the image's width).
    x_factor_.resize(static_cast<size_t>(depth_m.cols));
    for (int u = 0; u < depth_m.cols; ++u)
        x_factor_[static_cast<size_t>(u)] = (static_cast<float>(u) - cx) * inv_f;
    const cloud::CloudKernels& kernels = cloud::simdCloudKernels();
    forRowStripes(0, depth_m.rows, [&](int first, int end) {
        for (int v = first; v < end; ++v) {
            const size_t from = row_first_[static_cast<size_t>(v)];
            const size_t points = row_first_[static_cast<size_t>(v) + 1] - from;
            kernels.points_row(depth_m.ptr<float>(v), left_rectified.ptr<uint8_t>(v),
                               x_factor_.data(), (static_cast<float>(v) - cy) * inv_f, depth_m.cols,
                               points, cloud.data() + from);
        }
    });
}

void PointCloudBuilder::colours(const cv::Mat& depth_m, const cv::Mat& left_rectified_colour,
                                std::vector<CloudColour>& colours) const
{
    CV_Assert(depth_m.type() == CV_32FC1 && left_rectified_colour.type() == CV_8UC3 &&
              depth_m.size() == left_rectified_colour.size() && depth_m.data == built_from_ &&
              row_first_.size() == static_cast<size_t>(depth_m.rows) + 1);
    colours.reserve(depth_m.total());
    colours.resize(row_first_.back());
    forRowStripes(0, depth_m.rows, [&](int first, int end) {
        for (int v = first; v < end; ++v) {
            const float* z = depth_m.ptr<float>(v);
            const uint8_t* bgr = left_rectified_colour.ptr<uint8_t>(v);
            CloudColour* colour = colours.data() + row_first_[static_cast<size_t>(v)];
            for (int u = 0; u < depth_m.cols; ++u) {
                if (!(z[u] > 0.0f))
                    continue;
                *colour++ = CloudColour{bgr[3 * u + 2], bgr[3 * u + 1], bgr[3 * u]};
            }
        }
    });
}

} // namespace stereod
