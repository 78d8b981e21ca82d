#include "pipeline/triangulation.hpp"

#include <bit>
#include <cstdint>
#include <limits>

#include <opencv2/core/utility.hpp>

namespace stereod {

namespace {

// Depth of rows [rows.start, rows.end) in single precision, the validity test a select
// rather than a branch: the division per pixel is the stage's whole cost. Holds
// references only, like the rectifier's RemapRows: cv::parallel_for_ takes it by
// reference, without the heap.
class DepthRows final : public cv::ParallelLoopBody {
  public:
    DepthRows(const cv::Mat& disparity_px, float fb, float doffs, cv::Mat& depth_m)
        : disparity_(disparity_px), fb_(fb), doffs_(doffs), depth_(depth_m)
    {
    }

    void operator()(const cv::Range& rows) const override
    {
        constexpr float kInfinity = std::numeric_limits<float>::infinity();
        for (int y = rows.start; y < rows.end; ++y) {
            const float* d = disparity_.ptr<float>(y);
            float* z = depth_.ptr<float>(y);
            for (int x = 0; x < disparity_.cols; ++x) {
                const float denominator = d[x] + doffs_;
                // +inf and NaN fail the test too: both end as 0 (invalid). The division
                // is made for every pixel and the invalid ones masked to +0 by their bits:
                // a condition would become a branch, and keep the loop from being vector
                // code.
                const bool valid = (denominator > 0.0f) & (denominator < kInfinity);
                const uint32_t keep = 0u - static_cast<uint32_t>(valid);
                z[x] = std::bit_cast<float>(std::bit_cast<uint32_t>(fb_ / denominator) & keep);
            }
        }
    }

  private:
    const cv::Mat& disparity_;
    float fb_;
    float doffs_;
    cv::Mat& depth_;
};

} // namespace

void disparityToDepth(const cv::Mat& disparity_px, const RectifiedGeometry& geometry,
                      cv::Mat& depth_m)
{
    CV_Assert(disparity_px.type() == CV_32FC1);
    depth_m.create(disparity_px.size(), CV_32FC1);
    const DepthRows body(disparity_px, static_cast<float>(geometry.focal_px * geometry.baseline_m),
                         static_cast<float>(geometry.doffs_px), depth_m);
    // Two stripes per core at most: the rows are cheap, the hand-over is not.
    cv::parallel_for_(cv::Range(0, depth_m.rows), body, 2.0 * cv::getNumThreads());
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
