#include "pipeline/cloud/cloud_kernels.hpp"

namespace stereod::cloud {
namespace {

size_t pointsRow(const float* z, const uint8_t* grey, const float* x_factor, float row_factor,
                 int width, size_t points, CloudPoint* out)
{
    size_t written = 0;
    for (int u = 0; u < width && written < points; ++u) {
        if (!(z[u] > 0.0f))
            continue;
        out[written++] =
            CloudPoint{x_factor[u] * z[u], row_factor * z[u], z[u], static_cast<float>(grey[u])};
    }
    return written;
}

} // namespace

const CloudKernels& scalarCloudKernels()
{
    static const CloudKernels kernels{"scalar", pointsRow};
    return kernels;
}

} // namespace stereod::cloud
