// The cloud kernel on SIMD through Highway: compiled once per target and dispatched at run
// time. Same contract and same points as the scalar reference (cloud_kernels_scalar.cpp):
// a vector of pixels' coordinates is made at once, compressed to the valid ones and
// stored interleaved as points.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/cloud/cloud_kernels_simd.cpp"
#include <vector>

#include <hwy/foreach_target.h> // IWYU pragma: keep
#include <hwy/highway.h>

#include "pipeline/cloud/cloud_kernels.hpp"
#include "pipeline/simd_targets.hpp"

HWY_BEFORE_NAMESPACE();
namespace stereod::cloud {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

size_t PointsRow(const float* z, const uint8_t* grey, const float* x_factor, float row_factor,
                 int width, size_t points, CloudPoint* out)
{
    static_assert(sizeof(CloudPoint) == 4 * sizeof(float), "a point is four packed floats");
    const hn::ScalableTag<float> d;
    const hn::Rebind<int32_t, decltype(d)> di;
    const hn::Rebind<uint8_t, decltype(d)> d8;
    const size_t n = hn::Lanes(d);
    const auto zero = hn::Zero(d);
    const auto v_row = hn::Set(d, row_factor);
    auto* floats = reinterpret_cast<float*>(out);
    size_t written = 0;
    int u = 0;
    // A vector's store writes n whole points, valid or not, from the next one on: only
    // while the row has room for them (the next row's points may be another thread's).
    for (; u + static_cast<int>(n) <= width && written + n <= points; u += static_cast<int>(n)) {
        const auto depth = hn::LoadU(d, z + u);
        const auto valid = hn::Gt(depth, zero);
        if (hn::AllFalse(d, valid))
            continue;
        const auto x = hn::Mul(hn::LoadU(d, x_factor + u), depth);
        const auto y = hn::Mul(v_row, depth);
        const auto intensity = hn::ConvertTo(d, hn::PromoteTo(di, hn::LoadU(d8, grey + u)));
        hn::StoreInterleaved4(hn::Compress(x, valid), hn::Compress(y, valid),
                              hn::Compress(depth, valid), hn::Compress(intensity, valid), d,
                              floats + 4 * written);
        written += hn::CountTrue(d, valid);
    }
    return written + scalarCloudKernels().points_row(z + u, grey + u, x_factor + u, row_factor,
                                                     width - u, points - written, out + written);
}

const char* TargetName()
{
    return hwy::TargetName(HWY_TARGET);
}

// NOLINTNEXTLINE(google-readability-namespace-comments)
} // namespace HWY_NAMESPACE
} // namespace stereod::cloud
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace stereod::cloud {

HWY_EXPORT(PointsRow);
HWY_EXPORT(TargetName);

namespace {

// The kernels of the target Highway has chosen.
CloudKernels chosenKernels()
{
    return CloudKernels{HWY_DYNAMIC_DISPATCH(TargetName)(), HWY_DYNAMIC_DISPATCH(PointsRow)};
}

} // namespace

const CloudKernels& simdCloudKernels()
{
    return chosenTable(chosenKernels);
}

std::vector<CloudKernels> simdCloudKernelsOfEveryTarget()
{
    return tablesOfEveryTarget(chosenKernels);
}

} // namespace stereod::cloud
#endif
