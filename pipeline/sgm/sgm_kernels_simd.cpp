// The SGM kernels on SIMD through Highway: compiled once per target (AVX2, SSE4, NEON,
// ...) and dispatched at run time. Same contract and same integers as the scalar
// reference (sgm_kernels_scalar.cpp); vectors are capped at 32 bytes, so a row of `lanes`
// disparities (a multiple of kLaneAlign) is always a whole number of vectors.

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/sgm/sgm_kernels_simd.cpp"
#include <hwy/foreach_target.h>   // IWYU pragma: keep

#include <hwy/highway.h>

#include <algorithm>
#include <bit>
#include <cstring>

#include "pipeline/sgm/sgm_kernels.hpp"

HWY_BEFORE_NAMESPACE();
namespace stereod::sgm {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

#if HWY_TARGET == HWY_SCALAR
// Highway's one-lane fallback, for a processor with no SIMD target: the scalar reference.
void CensusRow(const uint8_t* center, size_t stride, int width, int census_width,
               int census_height, uint8_t* const* planes)
{
    scalarKernels().census_row(center, stride, width, census_width, census_height, planes);
}
void CostRow(const CensusRows& census, int width, int min_disparity, int num_disparities,
             int lanes, uint8_t cost_invalid, uint8_t* cost)
{
    scalarKernels().cost_row(census, width, min_disparity, num_disparities, lanes, cost_invalid,
                             cost);
}
void PathAlongRow(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                  bool forward, bool first, uint8_t* scratch, uint16_t* sum)
{
    scalarKernels().path_along_row(cost, p2, p1, width, lanes, forward, first, scratch, sum);
}
void PathFromAbove(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                   int dx, bool first, const uint8_t* prev, uint8_t* cur, uint16_t* sum)
{
    scalarKernels().path_from_above(cost, p2, p1, width, lanes, dx, first, prev, cur, sum);
}
void Winners(const uint16_t* sum, int width, int min_disparity, int num_disparities, int lanes,
             Winner* out, uint32_t* right_best, uint32_t* scratch)
{
    scalarKernels().winners(sum, width, min_disparity, num_disparities, lanes, out, right_best,
                            scratch);
}
#else

using D8 = hn::CappedTag<uint8_t, kLaneAlign>;
using D16 = hn::Repartition<uint16_t, D8>;        // same bytes, half the lanes
using DNarrow8 = hn::Rebind<uint8_t, D16>;        // as many bytes as D16 has lanes
using D32 = hn::Repartition<uint32_t, D8>;

// Smallest byte of a vector.
HWY_INLINE uint8_t minOfBytes(hn::Vec<D8> v)
{
    const D16 d16;
    const auto wide = hn::BitCast(d16, v);
    const auto low = hn::And(wide, hn::Set(d16, uint16_t{0xFF}));
    const auto high = hn::ShiftRight<8>(wide);
    return static_cast<uint8_t>(hn::GetLane(hn::MinOfLanes(d16, hn::Min(low, high))));
}

void CensusRow(const uint8_t* center, size_t stride, int width, int census_width,
               int census_height, uint8_t* const* planes)
{
    const D8 d;
    const int n = static_cast<int>(hn::Lanes(d));
    const int rx = census_width / 2;
    const int ry = census_height / 2;
    const int bits = census_width * census_height - 1;
    const int plane_count = (bits + 7) / 8;
    // The offset of the neighbour behind census bit `bit`: raster order over the window,
    // the centre skipped.
    const int centre = ry * census_width + rx;
    const auto offset = [&](int bit) {
        const int index = bit < centre ? bit : bit + 1;
        return static_cast<std::ptrdiff_t>(index / census_width - ry) *
                   static_cast<std::ptrdiff_t>(stride) +
               (index % census_width - rx);
    };
    int x = 0;
    for (; x + n <= width; x += n) {
        const auto c = hn::LoadU(d, center + x);
        // One plane (8 neighbours) at a time: scalable vector types cannot form arrays.
        for (int p = 0; p < plane_count; ++p) {
            auto acc = hn::Zero(d);
            for (int bit = 8 * p; bit < std::min(bits, 8 * p + 8); ++bit) {
                const uint8_t* neighbour = center + offset(bit);
                const auto darker = hn::Lt(hn::LoadU(d, neighbour + x), c);
                acc = hn::Or(acc, hn::IfThenElseZero(
                                      darker, hn::Set(d, static_cast<uint8_t>(1u << (bit % 8)))));
            }
            hn::StoreU(acc, d, planes[p] + x);
        }
    }
    for (; x < width; ++x) {   // the tail, one pixel at a time
        uint8_t bytes[8] = {};
        int bit = 0;
        for (int dy = -ry; dy <= ry; ++dy)
            for (int dx = -rx; dx <= rx; ++dx) {
                if (dy == 0 && dx == 0)
                    continue;
                const uint8_t neighbour = center[static_cast<std::ptrdiff_t>(dy) *
                                                     static_cast<std::ptrdiff_t>(stride) + dx + x];
                if (neighbour < center[x])
                    bytes[bit / 8] = static_cast<uint8_t>(bytes[bit / 8] | (1u << (bit % 8)));
                ++bit;
            }
        for (int p = 0; p < plane_count; ++p)
            planes[p][x] = bytes[p];
    }
}

void CostRow(const CensusRows& census, int width, int min_disparity, int num_disparities,
             int lanes, uint8_t cost_invalid, uint8_t* cost)
{
    const D8 d;
    const int n = static_cast<int>(hn::Lanes(d));
    for (int x = 0; x < width; ++x) {
        uint8_t* c = cost + static_cast<size_t>(x) * static_cast<size_t>(lanes);
        // right_reversed index of lane 0: x - min_disparity = width - 1 - j.
        const std::ptrdiff_t j0 = width - 1 - x + min_disparity;
        for (int k0 = 0; k0 < lanes; k0 += n) {
            auto distance = hn::Zero(d);
            for (int p = 0; p < census.planes; ++p) {
                const auto l = hn::Set(d, census.left[p][x]);
                const auto r = hn::LoadU(d, census.right_reversed[p] + j0 + k0);
                distance = hn::Add(distance, hn::PopulationCount(hn::Xor(l, r)));
            }
            hn::StoreU(distance, d, c + k0);
        }
        // Lanes whose right pixel is outside the image, and the padding lanes.
        const int k_lo = std::max(0, x - min_disparity - width + 1);
        const int k_hi = std::min(num_disparities - 1, x - min_disparity);
        if (k_hi < k_lo) {
            std::memset(c, cost_invalid, static_cast<size_t>(lanes));
            continue;
        }
        std::memset(c, cost_invalid, static_cast<size_t>(k_lo));
        std::memset(c + k_hi + 1, cost_invalid, static_cast<size_t>(lanes - k_hi - 1));
    }
}

// One path step (see step() in the scalar reference). Also keeps the smallest L of the
// block in its byte 0, which the next step of the path reads as its min L(p-r).
HWY_INLINE void Step(const uint8_t* cost, const uint8_t* prev, uint8_t p1, uint8_t p2,
                     int lanes, bool first, uint8_t* out, uint16_t* sum)
{
    const D8 d;
    const D16 dw;
    const DNarrow8 dn;
    const int n = static_cast<int>(hn::Lanes(d));
    const int nw = static_cast<int>(hn::Lanes(dw));
    uint8_t* l = out + kPathPad;
    auto running_min = hn::Set(d, uint8_t{255});
    // Adds the L values just stored at l + k0 into the 16-bit sums, widened from memory.
    auto accumulate = [&](int k0) {
        for (int h = k0; h < k0 + n; h += nw) {
            const auto wide = hn::PromoteTo(dw, hn::LoadU(dn, l + h));
            hn::StoreU(first ? wide : hn::Add(hn::LoadU(dw, sum + h), wide), dw, sum + h);
        }
    };
    if (prev == nullptr) {
        for (int k0 = 0; k0 < lanes; k0 += n) {
            const auto v = hn::LoadU(d, cost + k0);
            hn::StoreU(v, d, l + k0);
            running_min = hn::Min(running_min, v);
            accumulate(k0);
        }
        out[0] = minOfBytes(running_min);
        return;
    }
    const uint8_t* lp = prev + kPathPad;
    const uint8_t min_prev = prev[0];
    const auto v_min_prev = hn::Set(d, min_prev);
    const auto v_p1 = hn::Set(d, p1);
    const auto jump = hn::SaturatedAdd(v_min_prev, hn::Set(d, p2));
    for (int k0 = 0; k0 < lanes; k0 += n) {
        const auto same = hn::LoadU(d, lp + k0);
        const auto lower = hn::SaturatedAdd(hn::LoadU(d, lp + k0 - 1), v_p1);
        const auto upper = hn::SaturatedAdd(hn::LoadU(d, lp + k0 + 1), v_p1);
        const auto best = hn::Min(hn::Min(same, lower), hn::Min(upper, jump));
        const auto v = hn::SaturatedAdd(hn::LoadU(d, cost + k0), hn::Sub(best, v_min_prev));
        hn::StoreU(v, d, l + k0);
        running_min = hn::Min(running_min, v);
        accumulate(k0);
    }
    out[0] = minOfBytes(running_min);
}

void ClearPads(uint8_t* block, int lanes)
{
    std::memset(block, 255, kPathPad);
    std::memset(block + kPathPad + lanes, 255, kPathPad);
}

void PathAlongRow(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                  bool forward, bool first, uint8_t* scratch, uint16_t* sum)
{
    const size_t block = pathBlockBytes(lanes);
    uint8_t* a = scratch;
    uint8_t* b = scratch + block;
    ClearPads(a, lanes);
    ClearPads(b, lanes);
    const uint8_t* prev = nullptr;
    for (int i = 0; i < width; ++i) {
        const int x = forward ? i : width - 1 - i;
        const size_t at = static_cast<size_t>(x) * static_cast<size_t>(lanes);
        Step(cost + at, prev, p1, p2[x], lanes, first, a, sum + at);
        prev = a;
        std::swap(a, b);
    }
}

void PathFromAbove(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                   int dx, bool first, const uint8_t* prev, uint8_t* cur, uint16_t* sum)
{
    const size_t block = pathBlockBytes(lanes);
    for (int x = 0; x < width; ++x) {
        const int xp = x + dx;
        const uint8_t* from =
            (prev != nullptr && xp >= 0 && xp < width) ? prev + static_cast<size_t>(xp) * block
                                                       : nullptr;
        uint8_t* out = cur + static_cast<size_t>(x) * block;
        ClearPads(out, lanes);
        const size_t at = static_cast<size_t>(x) * static_cast<size_t>(lanes);
        Step(cost + at, from, p1, p2[x], lanes, first, out, sum + at);
    }
}

void Winners(const uint16_t* sum, int width, int min_disparity, int num_disparities, int lanes,
             Winner* out, uint32_t* right_best, uint32_t* scratch)
{
    const D16 d16;
    const D32 d32;
    const hn::Rebind<uint16_t, D32> dn16;   // as many u16 lanes as a u32 vector has
    const int n16 = static_cast<int>(hn::Lanes(d16));
    const int n32 = static_cast<int>(hn::Lanes(d32));
    const auto iota16 = hn::Iota(d16, 0);
    const auto iota32 = hn::Iota(d32, 0);
    const auto none16 = hn::Set(d16, uint16_t{0xFFFF});

    // The right view's best, indexed backwards (j = width - 1 - xr) so that the lanes of
    // one left pixel are consecutive; a margin on both sides takes the lanes whose right
    // pixel lies outside the row.
    const std::ptrdiff_t margin = lanes + std::abs(min_disparity) + kLaneAlign;
    uint32_t* backwards = scratch + margin;
    std::fill(scratch, scratch + winnersScratch(width, min_disparity, lanes), 0xFFFFFFFFu);

    for (int x = 0; x < width; ++x) {
        const uint16_t* s = sum + static_cast<size_t>(x) * static_cast<size_t>(lanes);
        auto v_min = none16;
        for (int k0 = 0; k0 < num_disparities; k0 += n16)
            v_min = hn::Min(v_min, hn::LoadU(d16, s + k0));
        const uint16_t best_sum = hn::GetLane(hn::MinOfLanes(d16, v_min));
        const auto v_best = hn::Set(d16, best_sum);
        int best = 0;
        for (int k0 = 0; k0 < num_disparities; k0 += n16) {
            const intptr_t at = hn::FindFirstTrue(d16, hn::Eq(hn::LoadU(d16, s + k0), v_best));
            if (at >= 0) {
                best = k0 + static_cast<int>(at);
                break;
            }
        }
        // The best sum outside best-1 .. best+1.
        auto v_second = none16;
        const auto below = hn::Set(d16, static_cast<uint16_t>(best - 1));   // 0xFFFF for 0
        const auto at = hn::Set(d16, static_cast<uint16_t>(best));
        const auto above = hn::Set(d16, static_cast<uint16_t>(best + 1));
        for (int k0 = 0; k0 < num_disparities; k0 += n16) {
            const auto k = hn::Add(iota16, hn::Set(d16, static_cast<uint16_t>(k0)));
            const auto near = hn::Or(hn::Or(hn::Eq(k, below), hn::Eq(k, at)), hn::Eq(k, above));
            v_second = hn::Min(v_second, hn::IfThenElse(near, none16, hn::LoadU(d16, s + k0)));
        }
        out[x] = Winner{static_cast<uint16_t>(best), best_sum,
                        hn::GetLane(hn::MinOfLanes(d16, v_second))};

        uint32_t* row = backwards + (width - 1 - x + min_disparity);
        for (int k0 = 0; k0 < num_disparities; k0 += n32) {
            const auto sums = hn::PromoteTo(d32, hn::LoadU(dn16, s + k0));
            const auto packed = hn::Or(hn::ShiftLeft<16>(sums),
                                       hn::Add(iota32, hn::Set(d32, static_cast<uint32_t>(k0))));
            hn::StoreU(hn::Min(hn::LoadU(d32, row + k0), packed), d32, row + k0);
        }
    }
    for (int xr = 0; xr < width; ++xr)
        right_best[xr] = backwards[width - 1 - xr];
}

#endif // HWY_TARGET == HWY_SCALAR

const char* TargetName()
{
    return hwy::TargetName(HWY_TARGET);
}

// NOLINTNEXTLINE(google-readability-namespace-comments)
} // namespace HWY_NAMESPACE
} // namespace stereod::sgm
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace stereod::sgm {

HWY_EXPORT(CensusRow);
HWY_EXPORT(CostRow);
HWY_EXPORT(PathAlongRow);
HWY_EXPORT(PathFromAbove);
HWY_EXPORT(Winners);
HWY_EXPORT(TargetName);

const SgmKernels& simdKernels()
{
    static const SgmKernels kernels = [] {
        // Choose the target now, so that the table holds the chosen functions rather
        // than the first-call trampolines.
        hwy::GetChosenTarget().Update(hwy::SupportedTargets());
        return SgmKernels{HWY_DYNAMIC_DISPATCH(TargetName)(),  HWY_DYNAMIC_DISPATCH(CensusRow),
                          HWY_DYNAMIC_DISPATCH(CostRow),      HWY_DYNAMIC_DISPATCH(PathAlongRow),
                          HWY_DYNAMIC_DISPATCH(PathFromAbove), HWY_DYNAMIC_DISPATCH(Winners)};
    }();
    return kernels;
}

} // namespace stereod::sgm
#endif
