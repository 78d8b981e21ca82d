// The remap kernel on SIMD through Highway: compiled once per target and dispatched at
// run time. Same contract and same bytes as the scalar reference
// (remap_kernels_scalar.cpp): the neighbours are gathered as the reference gathers them,
// and the blend runs in 32-bit lanes.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/resample/remap_kernels_simd.cpp"
#include <vector>

#include <hwy/foreach_target.h> // IWYU pragma: keep
#include <hwy/highway.h>

#include "pipeline/resample/remap_kernels.hpp"
#include "pipeline/simd_targets.hpp"

HWY_BEFORE_NAMESPACE();
namespace stereod::resample {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

void RemapRow(const RemapSource& src, const int32_t* offsets, const int16_t* xy,
              const uint16_t* frac, int width, uint8_t* out)
{
    const hn::ScalableTag<int32_t> d;
    const hn::Rebind<uint32_t, decltype(d)> du;
    const hn::Rebind<uint16_t, decltype(d)> d16;
    const hn::Rebind<uint8_t, decltype(d)> d8;
    const int n = static_cast<int>(hn::Lanes(d));
    const auto byte = hn::Set(d, 0xFF);
    const auto step_mask = hn::Set(d, (1 << kInterBits) - 1);
    const auto tab = hn::Set(d, 1 << kInterBits);
    const auto rounding = hn::Set(d, 1 << (2 * kInterBits - 1));
    const auto widen = [&](const uint16_t* p) {
        return hn::BitCast(d, hn::PromoteTo(du, hn::LoadU(d16, p)));
    };
    // One row of the neighbourhood along x: left * 32 + (right - left) * fx.
    const auto along = [&](hn::Vec<decltype(d)> pair, hn::Vec<decltype(d)> fx) {
        const auto left = hn::And(pair, byte);
        const auto right = hn::ShiftRight<8>(pair);
        return hn::Add(hn::ShiftLeft<kInterBits>(left), hn::Mul(hn::Sub(right, left), fx));
    };
    // Gathered by scalar loads in chunks (remap_kernels.hpp), blended a vector at a time.
    constexpr int kChunk = 256;
    HWY_ALIGN uint16_t top[kChunk];
    HWY_ALIGN uint16_t bottom[kChunk];
    for (int x0 = 0; x0 < width; x0 += kChunk) {
        const int count = width - x0 < kChunk ? width - x0 : kChunk;
        gatherNeighbours(src, offsets + x0, xy + 2 * x0, count, top, bottom);
        int i = 0;
        for (; i + n <= count; i += n) {
            const auto f = widen(frac + x0 + i);
            const auto fx = hn::And(f, step_mask);
            const auto fy = hn::And(hn::ShiftRight<kInterBits>(f), step_mask);
            const auto t = along(widen(top + i), fx);
            const auto b = along(widen(bottom + i), fx);
            const auto sum =
                hn::Add(hn::Add(hn::Mul(t, hn::Sub(tab, fy)), hn::Mul(b, fy)), rounding);
            hn::StoreU(hn::DemoteTo(d8, hn::ShiftRight<2 * kInterBits>(sum)), d8, out + x0 + i);
        }
        for (; i < count; ++i)
            out[x0 + i] = blendNeighbours(top[i], bottom[i], frac[x0 + i]);
    }
}

const char* TargetName()
{
    return hwy::TargetName(HWY_TARGET);
}

// NOLINTNEXTLINE(google-readability-namespace-comments)
} // namespace HWY_NAMESPACE
} // namespace stereod::resample
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace stereod::resample {

HWY_EXPORT(RemapRow);
HWY_EXPORT(TargetName);

namespace {

// The kernels of the target Highway has chosen.
RemapKernels chosenKernels()
{
    return RemapKernels{HWY_DYNAMIC_DISPATCH(TargetName)(), HWY_DYNAMIC_DISPATCH(RemapRow)};
}

} // namespace

const RemapKernels& simdRemapKernels()
{
    static const RemapKernels kernels = tableOfChosenTarget(chosenKernels);
    return kernels;
}

std::vector<RemapKernels> simdRemapKernelsOfEveryTarget()
{
    simdRemapKernels();
    return tablesOfEveryTarget(chosenKernels);
}

} // namespace stereod::resample
#endif
