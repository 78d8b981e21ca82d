#include "pipeline/hidden_surfaces.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stereod {
namespace {

bool measured(float d)
{
    return std::isfinite(d) && d >= 0.0f;
}

// A shadow is as wide as its step. The left-right check and the speckle filter leave a
// few pixels of either surface unmeasured at the edge (wider), and a stray match inside
// splits it (narrower). A run of another width is not a shadow of these ends: a stray
// near match beside a textureless patch, say, whose bounds would reach far too near.
bool shadowWidth(int width_px, float step_px)
{
    const auto width = static_cast<float>(width_px);
    return width <= step_px + 3.0f + 0.1f * step_px && width >= 0.6f * step_px - 2.0f;
}

// A run's end is a surface, not a stray match, when kSurfacePx measured pixels from it
// (outward, from `first` by `direction`) agree within kSurfaceAgreementPx.
constexpr int kSurfacePx = 4;
constexpr float kSurfaceAgreementPx = 1.5f;

bool surfaceAt(const float* d, int width, int first, int direction)
{
    for (int i = 1; i < kSurfacePx; ++i) {
        const int x = first + i * direction;
        if (x < 0 || x >= width || !measured(d[x]) ||
            std::fabs(d[x] - d[first]) > kSurfaceAgreementPx)
            return false;
    }
    return true;
}

} // namespace

void hiddenSurfaceBounds(const cv::Mat& disparity_px, int row_begin, int row_end, cv::Mat& bound_px)
{
    CV_Assert(disparity_px.type() == CV_32FC1);
    bound_px.create(disparity_px.size(), CV_32FC1);
    constexpr float kNone = std::numeric_limits<float>::infinity();
    row_begin = std::max(row_begin, 0);
    row_end = std::min(row_end, disparity_px.rows);
    const int width = disparity_px.cols;
    for (int y = row_begin; y < row_end; ++y) {
        const float* d = disparity_px.ptr<float>(y);
        float* bound = bound_px.ptr<float>(y);
        std::fill(bound, bound + width, kNone);
        int x = 0;
        while (x < width) {
            if (measured(d[x])) {
                ++x;
                continue;
            }
            const int begin = x; // the run [begin, end) has no disparity
            while (x < width && !measured(d[x]))
                ++x;
            const int end = x;
            // Both ends measured: a run at the image's border has no edge to judge by.
            if (begin == 0 || end == width)
                continue;
            const float left = d[begin - 1];
            const float right = d[end];
            const float step = right - left;
            if (step <= kMinShadowStepPx || !shadowWidth(end - begin, step) ||
                !surfaceAt(d, width, begin - 1, -1) || !surfaceAt(d, width, end, +1))
                continue;
            for (int u = begin; u < end; ++u)
                bound[u] = std::max(0.0f, right - static_cast<float>(end - u));
        }
    }
}

} // namespace stereod
