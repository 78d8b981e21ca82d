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

// Neighbourhoods of kGroup output pixels that lie within kWindow bytes along one source
// row, or two rows one under the other (a rectification map moves about a pixel per output
// pixel, and down a row now and then): the rows' bytes are loaded once as a window each,
// and every pixel's pair is picked out of them by byte shuffles, rather than loaded pixel
// by pixel. A group whose neighbourhoods spread wider, one with a pixel on the edge or
// outside, and one whose windows would pass the image's end are gathered as the
// reference gathers them.
constexpr int kGroup = 8;
constexpr int kWindow = 16;
// The window starts this many bytes before the group's first neighbourhood, so that a
// map that steps back a little along the group still fits.
constexpr int kLead = 4;

#if HWY_TARGET == HWY_SCALAR
// Highway's one-lane fallback, for a processor with no SIMD target: the reference's gather.
void GatherNeighbours(const RemapSource& src, const int32_t* offsets, const int16_t* xy, int n,
                      uint16_t* top, uint16_t* bottom)
{
    gatherNeighbours(src, offsets, xy, n, top, bottom);
}
#else
void GatherNeighbours(const RemapSource& src, const int32_t* offsets, const int16_t* xy, int n,
                      uint16_t* top, uint16_t* bottom)
{
    const hn::FixedTag<int32_t, 4> d32;
    const hn::FixedTag<uint32_t, 4> du32;
    const hn::FixedTag<uint16_t, 4> d16_half;
    const hn::FixedTag<uint16_t, 8> d16;
    const hn::FixedTag<uint8_t, 16> d8;
    const size_t readable =
        static_cast<size_t>(src.rows - 1) * src.step + static_cast<size_t>(src.cols);
    const auto step = static_cast<int32_t>(src.step);
    const auto v_step = hn::Set(d32, step);
    // A pair's two bytes: its index in the window, then the one after.
    const auto pair_step = hn::Set(d16, uint16_t{0x0100});
    const auto pair_spread = hn::Set(d16, uint16_t{0x0101});
    // An index past the window's last pair, or a negative one, reads as a large unsigned
    // number.
    const auto pairs_in_window = hn::Set(du32, uint32_t{kWindow - 1});
    const auto in_window = [&](hn::Vec<decltype(d32)> index) {
        return hn::RebindMask(d32, hn::Lt(hn::BitCast(du32, index), pairs_in_window));
    };
    int i = 0;
    for (; i + kGroup <= n; i += kGroup) {
        // The window starts kLead bytes before the first pixel's neighbourhood, in its row
        // or, when the map climbs a row along the group, in the row above it: then the
        // first pixels are the ones in the row under.
        const int32_t first = offsets[i];
        const bool climbs = offsets[i + kGroup - 1] < first - kLead;
        const int32_t base = first - kLead - (climbs ? step : 0);
        if (base < 0 || static_cast<size_t>(base) + 2 * src.step + kWindow > readable) {
            gatherNeighbours(src, offsets + i, xy + 2 * i, kGroup, top + i, bottom + i);
            continue;
        }
        // Each pixel's index in the window of its top row: the group's first row, or the
        // one under it. (Edge and outside codes are negative: in neither.)
        const auto v_base = hn::Set(d32, base);
        const auto lo = hn::Sub(hn::LoadU(d32, offsets + i), v_base);
        const auto hi = hn::Sub(hn::LoadU(d32, offsets + i + 4), v_base);
        const auto lo_under = in_window(hn::Sub(lo, v_step));
        const auto hi_under = in_window(hn::Sub(hi, v_step));
        if (!hn::AllTrue(d32, hn::Or(in_window(lo), lo_under)) ||
            !hn::AllTrue(d32, hn::Or(in_window(hi), hi_under))) {
            gatherNeighbours(src, offsets + i, xy + 2 * i, kGroup, top + i, bottom + i);
            continue;
        }
        const auto lo_index = hn::IfThenElse(lo_under, hn::Sub(lo, v_step), lo);
        const auto hi_index = hn::IfThenElse(hi_under, hn::Sub(hi, v_step), hi);
        const auto index =
            hn::Combine(d16, hn::DemoteTo(d16_half, hi_index), hn::DemoteTo(d16_half, lo_index));
        const auto pick = hn::BitCast(d8, hn::Add(hn::Mul(index, pair_spread), pair_step));
        const uint8_t* window = src.data + base;
        const auto pairs = [&](const uint8_t* row) {
            return hn::BitCast(d16, hn::TableLookupBytes(hn::LoadU(d8, row), pick));
        };
        const auto first_row = pairs(window);
        const auto second_row = pairs(window + src.step);
        if (hn::AllFalse(d32, hn::Or(lo_under, hi_under))) {
            hn::StoreU(first_row, d16, top + i);
            hn::StoreU(second_row, d16, bottom + i);
            continue;
        }
        // The pixels whose top row is the second: 0xFFFF in their lanes.
        const auto one = hn::Set(d32, 1);
        const auto under =
            hn::Gt(hn::Combine(d16, hn::DemoteTo(d16_half, hn::IfThenElseZero(hi_under, one)),
                               hn::DemoteTo(d16_half, hn::IfThenElseZero(lo_under, one))),
                   hn::Zero(d16));
        hn::StoreU(hn::IfThenElse(under, second_row, first_row), d16, top + i);
        hn::StoreU(hn::IfThenElse(under, pairs(window + 2 * src.step), second_row), d16,
                   bottom + i);
    }
    if (i < n)
        gatherNeighbours(src, offsets + i, xy + 2 * i, n - i, top + i, bottom + i);
}
#endif // HWY_TARGET == HWY_SCALAR

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
    // Gathered in chunks, blended a vector at a time.
    constexpr int kChunk = 256;
    HWY_ALIGN uint16_t top[kChunk];
    HWY_ALIGN uint16_t bottom[kChunk];
    for (int x0 = 0; x0 < width; x0 += kChunk) {
        const int count = width - x0 < kChunk ? width - x0 : kChunk;
        GatherNeighbours(src, offsets + x0, xy + 2 * x0, count, top, bottom);
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
    return chosenTable(chosenKernels);
}

std::vector<RemapKernels> simdRemapKernelsOfEveryTarget()
{
    return tablesOfEveryTarget(chosenKernels);
}

} // namespace stereod::resample
#endif
