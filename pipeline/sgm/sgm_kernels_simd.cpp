// The SGM kernels on SIMD through Highway: compiled once per target (AVX2, SSE4, NEON,
// ...) and dispatched at run time. Same contract and same integers as the scalar
// reference (sgm_kernels_scalar.cpp); vectors are capped at 32 bytes, so a row of `lanes`
// disparities (a multiple of kLaneAlign) is always a whole number of vectors.

// Also compile for AVX3_DL (Ice Lake, Zen 4 and later): one instruction per byte popcount,
// which the cost row spends most of its time on.
#ifndef HWY_WANT_AVX3_DL
#define HWY_WANT_AVX3_DL
#endif

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "pipeline/sgm/sgm_kernels_simd.cpp"
#include <algorithm>
#include <bit>
#include <cstring>
#include <type_traits>
#include <vector>

#include <hwy/foreach_target.h> // IWYU pragma: keep
#include <hwy/highway.h>

#include "pipeline/sgm/sgm_kernels.hpp"
#include "pipeline/simd_targets.hpp"

HWY_BEFORE_NAMESPACE();
namespace stereod::sgm {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

#if HWY_TARGET == HWY_SCALAR
// Highway's one-lane fallback, for a processor with no SIMD target: the scalar reference.
void CensusRow(const uint8_t* center, size_t stride, int width, int census_width, int census_height,
               uint8_t* const* planes)
{
    scalarKernels().census_row(center, stride, width, census_width, census_height, planes);
}
void CostRow(const CensusRows& census, int width, int min_disparity, int num_disparities, int lanes,
             uint8_t cost_invalid, uint8_t* cost, const LaneSpan* spans)
{
    scalarKernels().cost_row(census, width, min_disparity, num_disparities, lanes, cost_invalid,
                             cost, spans);
}
void PathsForward(const uint8_t* cost, uint8_t p1, int width, int lanes, const AbovePaths& above,
                  const uint8_t* p2_along, uint8_t* along, const LaneSpan* spans)
{
    scalarKernels().paths_forward(cost, p1, width, lanes, above, p2_along, along, spans);
}
void WinnersBackward(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                     const PathRows& others, int min_disparity, int num_disparities,
                     uint8_t* path_scratch, uint16_t* sum_scratch, const WinnerRows& winners,
                     uint16_t* right_lane, uint16_t* scratch, const LaneSpan* spans)
{
    scalarKernels().winners_backward(cost, p2, p1, width, lanes, others, min_disparity,
                                     num_disparities, path_scratch, sum_scratch, winners,
                                     right_lane, scratch, spans);
}
void DecideRow(const WinnerRows& winners, const uint16_t* right_lane, int width,
               const DecideSettings& settings, int16_t* disparity, uint8_t* confidence,
               uint8_t* range_limit)
{
    scalarKernels().decide_row(winners, right_lane, width, settings, disparity, confidence,
                               range_limit);
}
void CostCurve(const CensusRows& census, int x, int width, int first_disparity, int count,
               uint16_t* curve)
{
    scalarKernels().cost_curve(census, x, width, first_disparity, count, curve);
}
void StepPenalties(const uint8_t* a, const uint8_t* b, int n, const uint8_t* by_step, uint8_t* p2)
{
    scalarKernels().step_penalties(a, b, n, by_step, p2);
}
void MedianRow(const int16_t* up, const int16_t* row, const int16_t* down, int width,
               int16_t invalid, int16_t* dst)
{
    scalarKernels().median_row(up, row, down, width, invalid, dst);
}
#else

using D8 = hn::CappedTag<uint8_t, kLaneAlign>;
using D16 = hn::Repartition<uint16_t, D8>; // same bytes, half the lanes
using D32 = hn::Repartition<uint32_t, D8>;

#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX2 // 32-byte vectors, and SSE4's phminposuw
// The smallest 16-bit lane of a vector's halves in lane 0 (its position in lane 1):
// SSE4's phminposuw, one instruction, rather than Highway's reduction, which also
// broadcasts the result to every lane.
HWY_INLINE __m128i MinPosOfU16(hn::Vec<D16> v)
{
    return _mm_minpos_epu16(
        _mm_min_epu16(_mm256_castsi256_si128(v.raw), _mm256_extracti128_si256(v.raw, 1)));
}

// Smallest 16-bit lane of a vector.
HWY_INLINE uint16_t MinOfU16(hn::Vec<D16> v)
{
    return static_cast<uint16_t>(_mm_cvtsi128_si32(MinPosOfU16(v)));
}

// The smallest 16-bit lane of v, at most 255, in every byte: broadcast from the vector
// register, with no trip through a general one.
HWY_INLINE hn::Vec<D8> BroadcastSmallest(hn::Vec<D16> v)
{
    return hn::Vec<D8>{_mm256_broadcastb_epi8(MinPosOfU16(v))};
}
#else
// Smallest 16-bit lane of a vector.
HWY_INLINE uint16_t MinOfU16(hn::Vec<D16> v)
{
    return hn::GetLane(hn::MinOfLanes(D16(), v));
}

// The smallest 16-bit lane of v, at most 255, in every byte.
HWY_INLINE hn::Vec<D8> BroadcastSmallest(hn::Vec<D16> v)
{
    return hn::Set(D8(), static_cast<uint8_t>(MinOfU16(v)));
}
#endif

// Smallest byte of a vector, in every byte: the smaller of each byte pair, then the
// smallest pair. It lies on the path along the row's chain from one pixel to the next,
// so its latency counts.
HWY_INLINE hn::Vec<D8> MinOfBytes(hn::Vec<D8> v)
{
    const D16 d16;
    const auto wide = hn::BitCast(d16, v);
    return BroadcastSmallest(
        hn::Min(hn::And(wide, hn::Set(d16, uint16_t{0xFF})), hn::ShiftRight<8>(wide)));
}

void CensusRow(const uint8_t* center, size_t stride, int width, int census_width, int census_height,
               uint8_t* const* planes)
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
    // One plane (8 neighbours) at a time: scalable vector types cannot form arrays.
    const int vector_end = width - width % n;
    for (int p = 0; p < plane_count; ++p) {
        std::ptrdiff_t offsets[8];
        const int first = 8 * p;
        const int count = std::min(bits, first + 8) - first;
        for (int i = 0; i < count; ++i)
            offsets[i] = offset(first + i);
        for (int x = 0; x < vector_end; x += n) {
            const auto c = hn::LoadU(d, center + x);
            auto acc = hn::Zero(d);
            for (int i = 0; i < count; ++i) {
                const auto darker = hn::Lt(hn::LoadU(d, center + offsets[i] + x), c);
                acc = hn::Or(acc,
                             hn::IfThenElseZero(darker, hn::Set(d, static_cast<uint8_t>(1u << i))));
            }
            hn::StoreU(acc, d, planes[p] + x);
        }
    }
    int x = vector_end;
    for (; x < width; ++x) { // the tail, one pixel at a time
        uint8_t bytes[8] = {};
        int bit = 0;
        for (int dy = -ry; dy <= ry; ++dy)
            for (int dx = -rx; dx <= rx; ++dx) {
                if (dy == 0 && dx == 0)
                    continue;
                const uint8_t neighbour =
                    center[static_cast<std::ptrdiff_t>(dy) * static_cast<std::ptrdiff_t>(stride) +
                           dx + x];
                if (neighbour < center[x])
                    bytes[bit / 8] = static_cast<uint8_t>(bytes[bit / 8] | (1u << (bit % 8)));
                ++bit;
            }
        for (int p = 0; p < plane_count; ++p)
            planes[p][x] = bytes[p];
    }
}

// f(std::integral_constant<int, count>()) for count in kFirst..kLast (the last for any
// count past it): a kernel instantiated per count, dispatched once per row.
template <int kLast, int kFirst = 0, class F> HWY_INLINE void WithCount(int count, const F& f)
{
    if constexpr (kFirst < kLast) {
        if (count != kFirst)
            return WithCount<kLast, kFirst + 1>(count, f);
    }
    f(std::integral_constant<int, kFirst>());
}

// cost_row() for kPlanes census planes: a count known to the compiler unrolls the planes
// and keeps the rows' pointers in registers (the cost stores could alias them as far as
// it knows, which would load them again for every vector).
template <int kPlanes>
void CostRowOf(const CensusRows& census, int width, int min_disparity, int num_disparities,
               int lanes, uint8_t cost_invalid, uint8_t* cost, const LaneSpan* spans)
{
    const D8 d;
    const int n = static_cast<int>(hn::Lanes(d));
    const auto iota = hn::Iota(d, 0);
    const auto invalid = hn::Set(d, cost_invalid);
    const uint8_t* left_rows[kPlanes];
    const uint8_t* right_rows[kPlanes];
    for (int p = 0; p < kPlanes; ++p) {
        left_rows[p] = census.left[p];
        right_rows[p] = census.right_reversed[p];
    }
    for (int x = 0; x < width; ++x) {
        uint8_t* c = cost + static_cast<size_t>(x) * static_cast<size_t>(lanes);
        // The lanes whose right pixel is inside the image, and not padding.
        const int k_lo = std::max(0, x - min_disparity - width + 1);
        const int k_hi = std::min(num_disparities - 1, x - min_disparity);
        const LaneInterval span = lanesOf(spans, x, lanes);
        if (k_hi < k_lo) {
            std::memset(c + span.first, cost_invalid, static_cast<size_t>(span.end - span.first));
            continue;
        }
        // right_reversed index of lane 0: x - min_disparity = width - 1 - j.
        const std::ptrdiff_t j0 = width - 1 - x + min_disparity;
        // The left pixel's census bytes, read once: the cost stores below may alias
        // any byte as far as the compiler knows, so it would read them again per vector.
        uint8_t left[kPlanes];
        for (int p = 0; p < kPlanes; ++p)
            left[p] = left_rows[p][x];
        const auto distance = [&](int k0) {
            auto sum = hn::Zero(d);
            for (int p = 0; p < kPlanes; ++p) {
                const auto l = hn::Set(d, left[p]);
                const auto r = hn::LoadU(d, right_rows[p] + j0 + k0);
                sum = hn::Add(sum, hn::PopulationCount(hn::Xor(l, r)));
            }
            return sum;
        };
        if (k_lo <= span.first && k_hi >= span.end - 1) { // every lane valid: most pixels
            for (int k0 = span.first; k0 < span.end; k0 += n)
                hn::StoreU(distance(k0), d, c + k0);
            continue;
        }
        const auto lo = hn::Set(d, static_cast<uint8_t>(k_lo)); // k_lo <= k_hi <= 255
        const auto hi = hn::Set(d, static_cast<uint8_t>(k_hi));
        for (int k0 = span.first; k0 < span.end; k0 += n) {
            if (k0 > k_hi || k0 + n <= k_lo) {
                hn::StoreU(invalid, d, c + k0);
                continue;
            }
            const auto k = hn::Add(iota, hn::Set(d, static_cast<uint8_t>(k0)));
            const auto outside = hn::Or(hn::Lt(k, lo), hn::Lt(hi, k));
            hn::StoreU(hn::IfThenElse(outside, invalid, distance(k0)), d, c + k0);
        }
    }
}

void CostRow(const CensusRows& census, int width, int min_disparity, int num_disparities, int lanes,
             uint8_t cost_invalid, uint8_t* cost, const LaneSpan* spans)
{
    // 1 .. 8 planes: census windows of up to 64 bits.
    WithCount<8, 1>(census.planes, [&](auto planes) {
        CostRowOf<planes()>(census, width, min_disparity, num_disparities, lanes, cost_invalid,
                            cost, spans);
    });
}

// The first step of a path over lanes first .. end-1: L = C, written to l; returns min L
// in every byte.
template <class Visit>
HWY_INLINE hn::Vec<D8> StartPath(const uint8_t* cost, int first, int end, uint8_t* l,
                                 const Visit& visit)
{
    const D8 d;
    const int n = static_cast<int>(hn::Lanes(d));
    auto running_min = hn::Set(d, uint8_t{255});
    for (int k0 = first; k0 < end; k0 += n) {
        const auto v = hn::LoadU(d, cost + k0);
        hn::StoreU(v, d, l + k0);
        running_min = hn::Min(running_min, v);
        visit(k0, v);
    }
    return MinOfBytes(running_min);
}

// One step of a path (see step() in the scalar reference): writes L to out + kPathPad and
// returns min L in every byte. prev == nullptr starts the path; v_min_prev holds min L of
// prev in every byte. `visit(k0, v)` sees each vector of L as it is made.
template <class Visit>
HWY_INLINE hn::Vec<D8> Step(const uint8_t* cost, const uint8_t* prev, hn::Vec<D8> v_min_prev,
                            hn::Vec<D8> v_p1, uint8_t p2, int lanes, uint8_t* out,
                            const Visit& visit)
{
    const D8 d;
    const int n = static_cast<int>(hn::Lanes(d));
    uint8_t* l = out + kPathPad;
    auto running_min = hn::Set(d, uint8_t{255});
    if (prev == nullptr)
        return StartPath(cost, 0, lanes, l, visit);
    const uint8_t* lp = prev + kPathPad;
    const auto jump = hn::SaturatedAdd(v_min_prev, hn::Set(d, p2));
    for (int k0 = 0; k0 < lanes; k0 += n) {
        const auto same = hn::LoadU(d, lp + k0);
        const auto lower = hn::SaturatedAdd(hn::LoadU(d, lp + k0 - 1), v_p1);
        const auto upper = hn::SaturatedAdd(hn::LoadU(d, lp + k0 + 1), v_p1);
        const auto best = hn::Min(hn::Min(same, lower), hn::Min(upper, jump));
        const auto v = hn::SaturatedAdd(hn::LoadU(d, cost + k0), hn::Sub(best, v_min_prev));
        hn::StoreU(v, d, l + k0);
        running_min = hn::Min(running_min, v);
        visit(k0, v);
    }
    return MinOfBytes(running_min);
}

// Step() over the lanes of `span` alone (spans, sgm_kernels.hpp): prev holds L inside
// prev_span and 255 in its guards, a lane beyond them counts as 255; writes out's guards.
// The branches pick, per vector, which of L(k), L(k - 1) and L(k + 1) prev holds.
template <class Visit>
HWY_INLINE hn::Vec<D8> StepInSpan(const uint8_t* cost, const uint8_t* prev, LaneInterval prev_span,
                                  hn::Vec<D8> v_min_prev, hn::Vec<D8> v_p1, uint8_t p2,
                                  LaneInterval span, uint8_t* out, const Visit& visit)
{
    const D8 d;
    const int n = static_cast<int>(hn::Lanes(d));
    uint8_t* l = out + kPathPad;
    const auto unreached = hn::Set(d, uint8_t{255});
    for (int g = 0; g < kLaneAlign; g += n) { // within the block: kPathPad == kLaneAlign
        hn::StoreU(unreached, d, l + span.first - kLaneAlign + g);
        hn::StoreU(unreached, d, l + span.end + g);
    }
    auto running_min = unreached;
    if (prev == nullptr)
        return StartPath(cost, span.first, span.end, l, visit);
    const uint8_t* lp = prev + kPathPad;
    const auto jump = hn::SaturatedAdd(v_min_prev, hn::Set(d, p2));
    for (int k0 = span.first; k0 < span.end; k0 += n) {
        auto best = jump;
        if (k0 >= prev_span.first && k0 < prev_span.end) {
            const auto same = hn::LoadU(d, lp + k0);
            const auto lower = hn::SaturatedAdd(hn::LoadU(d, lp + k0 - 1), v_p1);
            const auto upper = hn::SaturatedAdd(hn::LoadU(d, lp + k0 + 1), v_p1);
            best = hn::Min(hn::Min(same, lower), hn::Min(upper, jump));
        } else if (k0 + n == prev_span.first) { // only L(k + 1) of the last lane
            best = hn::Min(hn::SaturatedAdd(hn::LoadU(d, lp + k0 + 1), v_p1), jump);
        } else if (k0 == prev_span.end) { // only L(k - 1) of the first lane
            best = hn::Min(hn::SaturatedAdd(hn::LoadU(d, lp + k0 - 1), v_p1), jump);
        }
        const auto v = hn::SaturatedAdd(hn::LoadU(d, cost + k0), hn::Sub(best, v_min_prev));
        hn::StoreU(v, d, l + k0);
        running_min = hn::Min(running_min, v);
        visit(k0, v);
    }
    return MinOfBytes(running_min);
}

// paths_forward() for kAbove paths from above: a count known to the compiler unrolls the
// loop over them.
template <int kAbove, bool kSpans>
void PathsForwardOf(const uint8_t* cost, uint8_t p1, int width, int lanes, const AbovePaths& above,
                    const uint8_t* p2_along, uint8_t* along, const LaneSpan* spans)
{
    const D8 d;
    const size_t block = pathBlockBytes(lanes);
    const auto v_p1 = hn::Set(d, p1);
    const auto none = [](int, hn::Vec<D8>) {};
    auto v_min = hn::Zero(d); // min L of the along path's previous block, every byte
    // The paths' rows, copied out of `above`: the kernel's byte stores could alias them as
    // far as the compiler knows, which would reload them for every pixel.
    int dx[kAbove > 0 ? kAbove : 1] = {};
    const uint8_t* p2[kAbove > 0 ? kAbove : 1] = {};
    const uint8_t* prev_row[kAbove > 0 ? kAbove : 1] = {};
    uint8_t* cur_row[kAbove > 0 ? kAbove : 1] = {};
    for (int i = 0; i < kAbove; ++i) {
        dx[i] = above.dx[i];
        p2[i] = above.p2[i];
        prev_row[i] = above.prev[i];
        cur_row[i] = above.cur[i];
    }
    const LaneSpan* prev_spans = above.prev_spans;
    for (int x = 0; x < width; ++x) {
        const uint8_t* c = cost + static_cast<size_t>(x) * static_cast<size_t>(lanes);
        const LaneInterval span = lanesOf(spans, x, lanes);
        for (int i = 0; i < kAbove; ++i) {
            const int xp = x + dx[i];
            const uint8_t* from = (prev_row[i] != nullptr && xp >= 0 && xp < width)
                                      ? prev_row[i] + static_cast<size_t>(xp) * block
                                      : nullptr;
            const auto v_min_prev = hn::Set(d, from != nullptr ? from[0] : uint8_t{0});
            uint8_t* out = cur_row[i] + static_cast<size_t>(x) * block;
            if constexpr (kSpans) {
                const LaneInterval from_span =
                    from != nullptr ? lanesOf(prev_spans, xp, lanes) : LaneInterval{};
                out[0] = hn::GetLane(
                    StepInSpan(c, from, from_span, v_min_prev, v_p1, p2[i][x], span, out, none));
            } else {
                out[0] = hn::GetLane(Step(c, from, v_min_prev, v_p1, p2[i][x], lanes, out, none));
            }
        }
        if (along != nullptr) {
            const uint8_t* prev = x == 0 ? nullptr : along + static_cast<size_t>(x - 1) * block;
            uint8_t* out = along + static_cast<size_t>(x) * block;
            if constexpr (kSpans)
                v_min = StepInSpan(c, prev, x == 0 ? LaneInterval{} : lanesOf(spans, x - 1, lanes),
                                   v_min, v_p1, p2_along[x], span, out, none);
            else
                v_min = Step(c, prev, v_min, v_p1, p2_along[x], lanes, out, none);
        }
    }
}

void PathsForward(const uint8_t* cost, uint8_t p1, int width, int lanes, const AbovePaths& above,
                  const uint8_t* p2_along, uint8_t* along, const LaneSpan* spans)
{
    WithCount<3>(above.count, [&](auto count) { // the matcher has 1 or 3
        if (spans != nullptr)
            PathsForwardOf<count(), true>(cost, p1, width, lanes, above, p2_along, along, spans);
        else
            PathsForwardOf<count(), false>(cost, p1, width, lanes, above, p2_along, along, spans);
    });
}

// Summed path costs are at most 5 x 255 = 1275 < 2^11, so a sum and a 5-bit tag fit in
// 16 bits as sum << kTagBits | tag: comparing keys compares sums first, tags on ties.
constexpr int kTagBits = 5;
static_assert(5 * 255 < (1 << (16 - kTagBits)) - 1, "summed paths and tag fit in 16 bits");
static_assert(kWinnerGroup <= (1 << kTagBits), "a group index fits in the tag");

// winners_backward() for kOthers other paths: a count known to the compiler unrolls the
// sum and keeps the rows' pointers in registers. kWhole: num_disparities == lanes (every
// range of a multiple of kLaneAlign disparities), so no vector of a pixel's lanes reaches
// past the range and the per-vector tests fall away.
template <int kOthers, bool kSpans, bool kWhole>
void WinnersBackwardOf(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                       const PathRows& others, int min_disparity, int num_disparities,
                       uint8_t* path_scratch, uint16_t* sum_scratch, const WinnerRows& out,
                       uint16_t* right_lane, uint16_t* scratch, const LaneSpan* spans)
{
    const D8 d;
    const D16 d16;
    const hn::Half<D8> dh;
    const int n16 = static_cast<int>(hn::Lanes(d16));
    const size_t block = pathBlockBytes(lanes);
    const auto iota16 = hn::Iota(d16, 0);
    const auto none16 = hn::Set(d16, uint16_t{0xFFFF});
    const auto three16 = hn::Set(d16, uint16_t{3});
    const auto tag_mask = hn::Set(d16, uint16_t{(1u << kTagBits) - 1});
    const auto v_n16 = hn::Set(d16, static_cast<uint16_t>(n16));
    const auto v_p1 = hn::Set(d, p1);
    // Per lane k, its vector's index k / n16, the tag of a left pixel's keys: loaded with
    // the vector's sums rather than counted along them, one instruction fewer per vector.
    // (Vectors are at most 32 bytes: 16 lanes of 16 bits, so a tag of kTagBits counts
    // up to 512 lanes.)
    constexpr int kTaggedLanes = 16 << kTagBits;
    HWY_DASSERT(lanes <= kTaggedLanes);
    HWY_ALIGN uint16_t lane_tags[kTaggedLanes];
    for (int k0 = 0; k0 < lanes; k0 += n16)
        hn::Store(hn::Set(d16, static_cast<uint16_t>(k0 / n16)), d16, lane_tags + k0);
    // The vector index of a lane (k / n16) must fit the tag too.
    HWY_DASSERT(num_disparities / n16 <= (1 << kTagBits));

    // The right view's best sum and its lane, indexed backwards (j = width - 1 - xr) so
    // that the lanes of one left pixel are consecutive; a margin on both sides takes the
    // lanes whose right pixel lies outside the row.
    const size_t half = winnersScratch(width, min_disparity, lanes) / 2;
    const std::ptrdiff_t margin = lanes + std::abs(min_disparity) + kLaneAlign;
    std::fill(scratch, scratch + 2 * half, uint16_t{0xFFFF});
    uint16_t* back_sum = scratch + margin;
    uint16_t* back_lane = scratch + half + margin;
    // The last kWinnerGroup pixels, worked on together once their paths are summed, so that
    // the reductions of one pixel overlap with the next pixel's rather than waiting in
    // line: for pixel g of the group, its keys sum << kTagBits | (kWinnerGroup - 1 - g)
    // with 0xFFFF on both sides (the tag ranks a later pixel, of smaller k for the same
    // right pixel, first), and per lane the smallest sum << kTagBits | k / n16.
    const size_t group_stride = static_cast<size_t>(lanes) + 32;
    uint16_t* lane_best = sum_scratch + static_cast<size_t>(kWinnerGroup) * group_stride;
    std::fill(sum_scratch, sum_scratch + winnersSumScratch(lanes), uint16_t{0xFFFF});
    const auto keys_of = [&](int g) {
        return sum_scratch + static_cast<size_t>(g) * group_stride + 16;
    };

    // The lanes pixel x summed: its span's, within the range.
    const auto summed = [&](int x) {
        const LaneInterval span = lanesOf(spans, x, lanes);
        return LaneInterval{span.first, std::min(span.end, num_disparities)};
    };
    // With spans: the lanes of each group slot that hold a key, those its pixel summed.
    // Every other entry of the slot reads 0xFFFF, as in the full search, so that the right
    // view's pass below takes the group's minimum in registers: a gather through memory
    // would store and reload overlapping vectors one entry apart, which the processor
    // cannot forward from store to load.
    LaneInterval keyed[kWinnerGroup] = {};
    const auto rekey = [&](int g, LaneInterval span) {
        uint16_t* key = keys_of(g);
        const LaneInterval old = keyed[g];
        for (int k0 = old.first; k0 < std::min(old.end, span.first); k0 += n16)
            hn::StoreU(none16, d16, key + k0);
        for (int k0 = std::max(old.first, span.end); k0 < old.end; k0 += n16)
            hn::StoreU(none16, d16, key + k0);
        keyed[g] = span;
    };

    const auto finish_group = [&](int x_first, int count) {
        for (int g = 0; g < count; ++g) {
            const uint16_t* key = keys_of(g);
            const auto v_first = hn::LoadU(d16, lane_best + (2 * g) * n16);
            const auto v_next = hn::LoadU(d16, lane_best + (2 * g + 1) * n16);
            const uint16_t best_key = MinOfU16(v_first);
            const auto v_best = hn::Set(d16, best_key);
            const int best = (best_key & ((1 << kTagBits) - 1)) * n16 +
                             static_cast<int>(hn::FindFirstTrue(d16, hn::Eq(v_first, v_best)));
            // The best sum outside best-1 .. best+1. Those three k lie in different lanes,
            // so a lane whose smallest sum is at one of them offers its second smallest
            // (at another k, not near), and every other lane its smallest.
            // k - (best - 1) < 3 (unsigned) is near.
            const auto k_first = hn::Add(hn::Mul(hn::And(v_first, tag_mask), v_n16), iota16);
            const auto near =
                hn::Lt(hn::Sub(k_first, hn::Set(d16, static_cast<uint16_t>(best - 1))), three16);
            const uint16_t second = MinOfU16(hn::IfThenElse(near, v_next, v_first));
            const int x = x_first - g;
            const LaneInterval lanes_summed = kSpans ? keyed[g] : LaneInterval{0, num_disparities};
            const auto sum_at = [&](int k) {
                return k >= lanes_summed.first && k < lanes_summed.end
                           ? static_cast<uint16_t>(key[k] >> kTagBits)
                           : uint16_t{0};
            };
            out.best_lane[x] = static_cast<uint16_t>(best);
            out.best_sum[x] = static_cast<uint16_t>(best_key >> kTagBits);
            out.second_sum[x] =
                second == 0xFFFF ? second : static_cast<uint16_t>(second >> kTagBits);
            out.below_sum[x] = sum_at(best - 1);
            out.above_sum[x] = sum_at(best + 1);
            // A minimum at an end of the span that is not an end of the range: the true
            // one may lie beyond it (sgm_kernels.hpp).
            if (kSpans && ((best == lanes_summed.first && best > 0) ||
                           (best == lanes_summed.end - 1 && lanes_summed.end < num_disparities)))
                out.second_sum[x] = out.best_sum[x];
        }
        // The right view: pixel g of the group has j = j0 + g, so its lane for position
        // p0 is p0 - g. Keys of pixels past the row's ends, and margins, are 0xFFFF.
        const std::ptrdiff_t j0 = width - 1 - x_first + min_disparity;
        int p_first = 0;
        int p_end = num_disparities + count - 1;
        if constexpr (kSpans) {
            // Only the positions the group's lanes reach: the rest offer nothing.
            int first = num_disparities, end = 0;
            for (int g = 0; g < count; ++g) {
                first = std::min(first, keyed[g].first);
                end = std::max(end, keyed[g].end);
            }
            p_first = first;
            p_end = end + count - 1;
        }
        // The smallest key of the group's first `pixels` pixels at position p0.
        const auto group_min = [&](int p0, int pixels) {
            auto best_key = none16;
            for (int g = 0; g < pixels; ++g)
                best_key = hn::Min(best_key, hn::LoadU(d16, keys_of(g) + p0 - g));
            return best_key;
        };
        for (int p0 = p_first; p0 < p_end; p0 += n16) {
            // Every group but a row's last is whole: a count the compiler knows unrolls it.
            const auto best_key =
                count == kWinnerGroup ? group_min(p0, kWinnerGroup) : group_min(p0, count);
            const auto sums = hn::ShiftRight<kTagBits>(best_key);
            const auto g_of = hn::Sub(hn::Set(d16, static_cast<uint16_t>(kWinnerGroup - 1)),
                                      hn::And(best_key, tag_mask));
            const auto k = hn::Sub(hn::Add(iota16, hn::Set(d16, static_cast<uint16_t>(p0))), g_of);
            // This group's pixels lie left of the earlier groups': smaller k, so a tie
            // replaces.
            const auto old_sum = hn::LoadU(d16, back_sum + j0 + p0);
            const auto keep = hn::Lt(old_sum, sums);
            hn::StoreU(hn::Min(old_sum, sums), d16, back_sum + j0 + p0);
            hn::StoreU(hn::IfThenElse(keep, hn::LoadU(d16, back_lane + j0 + p0), k), d16,
                       back_lane + j0 + p0);
        }
    };

    const uint8_t* rows[kOthers > 0 ? kOthers : 1] = {};
    for (int i = 0; i < kOthers; ++i)
        rows[i] = others.rows[i];
    uint8_t* a = path_scratch;
    uint8_t* b = path_scratch + block;
    const uint8_t* prev = nullptr;
    LaneInterval prev_span{};
    auto v_min = hn::Zero(d);
    for (int x = width - 1; x >= 0; --x) {
        const size_t at = static_cast<size_t>(x) * static_cast<size_t>(lanes);
        const LaneInterval span = lanesOf(spans, x, lanes);
        const size_t block_at = static_cast<size_t>(x) * block + kPathPad;
        const int g = (width - 1 - x) % kWinnerGroup;
        uint16_t* key = sum_scratch + static_cast<size_t>(g) * group_stride + 16;
        const auto right_tag = hn::Set(d16, static_cast<uint16_t>(kWinnerGroup - 1 - g));
        auto best = none16; // per lane: smallest sum << kTagBits | k / n16
        auto next = none16; // per lane: the second smallest
        if constexpr (kSpans)
            rekey(g, summed(x));
        // Sums the paths for the lanes of this vector.
        const auto visit = [&](int k0, hn::Vec<D8> v) {
            if (!kWhole && k0 >= num_disparities)
                return;
            auto lo = hn::PromoteTo(d16, hn::LowerHalf(dh, v));
            auto hi = hn::PromoteTo(d16, hn::UpperHalf(dh, v));
            for (int i = 0; i < kOthers; ++i) { // each half widened as it is loaded
                const uint8_t* o = rows[i] + block_at + k0;
                lo = hn::Add(lo, hn::PromoteTo(d16, hn::LoadU(dh, o)));
                hi = hn::Add(hi, hn::PromoteTo(d16, hn::LoadU(dh, o + n16)));
            }
            lo = hn::ShiftLeft<kTagBits>(lo);
            hn::StoreU(hn::Or(lo, right_tag), d16, key + k0);
            lo = hn::Or(lo, hn::Load(d16, lane_tags + k0));
            next = hn::Min(next, hn::Max(best, lo));
            best = hn::Min(best, lo);
            if (kWhole || k0 + n16 < num_disparities) {
                hi = hn::ShiftLeft<kTagBits>(hi);
                hn::StoreU(hn::Or(hi, right_tag), d16, key + k0 + n16);
                hi = hn::Or(hi, hn::Load(d16, lane_tags + k0 + n16));
                next = hn::Min(next, hn::Max(best, hi));
                best = hn::Min(best, hi);
            }
        };
        if constexpr (kSpans)
            v_min = StepInSpan(cost + at, prev, prev_span, v_min, v_p1, p2[x], span, a, visit);
        else
            v_min = Step(cost + at, prev, v_min, v_p1, p2[x], lanes, a, visit);
        prev = a;
        prev_span = span;
        std::swap(a, b);
        hn::StoreU(best, d16, lane_best + (2 * g) * n16);
        hn::StoreU(next, d16, lane_best + (2 * g + 1) * n16);
        if (g == kWinnerGroup - 1 || x == 0)
            finish_group(x + g, g + 1);
    }
    // 0xFFFF where no lane reached the right pixel (a margin lane may have left its k).
    for (int xr = 0; xr < width; ++xr) {
        const int jr = width - 1 - xr;
        right_lane[xr] = back_sum[jr] >= (0xFFFF >> kTagBits) ? uint16_t{0xFFFF} : back_lane[jr];
    }
}

// decide_row() on 32-bit lanes: the reference's tests become masks, its divisions
// vector divisions of the same single-precision values, so that every lane computes what
// the reference computes for its pixel.
void DecideRow(const WinnerRows& w, const uint16_t* right_lane, int width, const DecideSettings& s,
               int16_t* disparity, uint8_t* confidence, uint8_t* range_limit)
{
    constexpr size_t kMaxChunk = 8;
    const hn::CappedTag<int32_t, kMaxChunk> d;
    const hn::Rebind<float, decltype(d)> df;
    const hn::Rebind<uint16_t, decltype(d)> du16;
    const hn::Rebind<int16_t, decltype(d)> di16;
    const hn::Rebind<uint8_t, decltype(d)> du8;
    const int n = static_cast<int>(hn::Lanes(d));
    const int num = s.num_disparities;
    const bool lr_check = s.lr_max_diff_px >= 0;
    const auto zero = hn::Zero(d);
    const auto one = hn::Set(d, 1);
    const auto none = hn::Set(d, 0xFFFF);
    const auto last_lane = hn::Set(d, num - 1);
    const auto min_disparity = hn::Set(d, s.min_disparity);
    const auto iota = hn::Iota(d, 0);
    // right_lane read as 32-bit words at byte offsets 2 xr: the low half is entry xr
    // (little-endian), the high half entry xr + 1, which rightLaneEntries() allows.
    const auto* right_words = reinterpret_cast<const int32_t*>(right_lane);

    // Pixels x0 .. x0 + n - 1 from the winners at `at` (the row's, or copies of its tail).
    const auto chunk = [&](int x0, const WinnerRows& at, size_t i, int16_t* disparity_out,
                           uint8_t* confidence_out, uint8_t* range_out) {
        const auto load = [&](const uint16_t* row) {
            return hn::PromoteTo(d, hn::LoadU(du16, row + i));
        };
        const auto x = hn::Add(iota, hn::Set(d, x0));
        const auto k = load(at.best_lane);
        const auto best = load(at.best_sum);
        const auto second = load(at.second_sum);
        const auto below = load(at.below_sum);
        const auto above = load(at.above_sum);
        const auto searchable = hn::Min(last_lane, hn::Sub(x, min_disparity));
        const auto searched = hn::Gt(searchable, hn::Set(d, -1));
        const auto cut = hn::Lt(searchable, last_lane);
        const auto near_end = hn::AndNot(cut, hn::Eq(k, last_lane));
        const auto beyond_edge =
            hn::And(cut, hn::Gt(k, hn::Sub(searchable, hn::Set(d, s.edge_margin_px))));
        const auto unique = hn::Gt(hn::Mul(second, hn::Set(d, 100)),
                                   hn::Mul(best, hn::Set(d, 100 + s.uniqueness_percent)));
        auto valid = hn::AndNot(hn::Or(near_end, beyond_edge), hn::And(searched, unique));
        auto lr_diff = zero;
        if (lr_check) {
            const auto xr = hn::Sub(hn::Sub(x, min_disparity), k);
            const auto in_row = hn::And(hn::Gt(xr, hn::Set(d, -1)), hn::Lt(xr, hn::Set(d, width)));
            const auto xr_inside = hn::Min(hn::Max(xr, zero), hn::Set(d, width - 1));
            const auto words = hn::GatherOffset(d, right_words, hn::Add(xr_inside, xr_inside));
            const auto right = hn::IfThenElse(in_row, hn::And(words, none), none);
            lr_diff = hn::Abs(hn::Sub(right, k));
            valid = hn::And(valid, hn::AndNot(hn::Gt(lr_diff, hn::Set(d, s.lr_max_diff_px)),
                                              hn::Ne(right, none)));
        }
        const auto inside = hn::And(hn::Gt(k, zero), hn::Lt(k, hn::Min(last_lane, searchable)));
        const auto curvature =
            hn::IfThenElseZero(inside, hn::Sub(hn::Add(below, above), hn::Add(best, best)));
        // (below - above) 16 / (2 curvature), rounded half away from zero; the quotient
        // lies at least 1 / 5100 from any half-integer unless it is one exactly, which
        // single precision keeps apart, so this equals the reference's integer division.
        const auto quotient =
            hn::Div(hn::ConvertTo(df, hn::Mul(hn::Sub(below, above), hn::Set(d, kSubpixel))),
                    hn::ConvertTo(df, hn::Max(hn::Add(curvature, curvature), one)));
        const auto offset = hn::IfThenElseZero(
            hn::Gt(curvature, zero),
            hn::ConvertTo(d, hn::Add(quotient, hn::CopySign(hn::Set(df, 0.5f), quotient))));
        const auto fixed =
            hn::Add(hn::Mul(hn::Add(min_disparity, k), hn::Set(d, kSubpixel)), offset);
        hn::StoreU(hn::DemoteTo(di16, hn::IfThenElse(valid, fixed, hn::Set(d, kNoDisparity))), di16,
                   disparity_out);

        // The reference's confidenceOf(), operation for operation.
        const auto gap = hn::Sub(second, best);
        const auto uniqueness =
            hn::Min(hn::Set(df, 1.0f), hn::Div(hn::ConvertTo(df, hn::Add(gap, gap)),
                                               hn::ConvertTo(df, hn::Max(best, one))));
        const auto sharpness = hn::Min(hn::Set(df, 1.0f), hn::Div(hn::ConvertTo(df, curvature),
                                                                  hn::Set(df, s.sharp_curvature)));
        const auto agreement =
            hn::IfThenElse(hn::RebindMask(df, hn::Eq(lr_diff, zero)), hn::Set(df, 1.0f),
                           hn::IfThenElse(hn::RebindMask(df, hn::Eq(lr_diff, one)),
                                          hn::Set(df, 0.7f), hn::Set(df, 0.4f)));
        const auto reach = hn::Div(hn::ConvertTo(df, hn::Add(searchable, one)),
                                   hn::Set(df, static_cast<float>(num)));
        const auto c = hn::Mul(
            hn::Mul(hn::Mul(hn::Mul(hn::Set(df, 255.0f), uniqueness),
                            hn::Add(hn::Set(df, 0.5f), hn::Mul(hn::Set(df, 0.5f), sharpness))),
                    agreement),
            reach);
        const auto rounded = hn::ConvertTo(d, hn::Add(c, hn::Set(df, 0.5f)));
        const auto level = hn::Min(hn::Max(rounded, one), hn::Set(d, 255));
        hn::StoreU(hn::DemoteTo(du8, hn::IfThenElseZero(valid, level)), du8, confidence_out);
        hn::StoreU(hn::DemoteTo(du8, hn::IfThenElseZero(hn::And(searched, near_end), one)), du8,
                   range_out);
    };

    int x = 0;
    for (; x + n <= width; x += n) {
        const size_t at = static_cast<size_t>(x);
        chunk(x, w, at, disparity + at, confidence + at, range_limit + at);
    }
    if (x == width)
        return;
    // The tail: its winners copied into a whole vector (the rest of it repeats the last
    // pixel), decided, and its pixels copied out.
    const size_t count = static_cast<size_t>(width - x);
    uint16_t fields[5][kMaxChunk];
    uint16_t* const rows[5] = {w.best_lane, w.best_sum, w.second_sum, w.below_sum, w.above_sum};
    for (size_t f = 0; f < 5; ++f)
        for (size_t i = 0; i < kMaxChunk; ++i)
            fields[f][i] = rows[f][static_cast<size_t>(x) + std::min(i, count - 1)];
    const WinnerRows tail{fields[0], fields[1], fields[2], fields[3], fields[4]};
    int16_t tail_disparity[kMaxChunk];
    uint8_t tail_confidence[kMaxChunk];
    uint8_t tail_range[kMaxChunk];
    chunk(x, tail, 0, tail_disparity, tail_confidence, tail_range);
    std::copy_n(tail_disparity, count, disparity + x);
    std::copy_n(tail_confidence, count, confidence + x);
    std::copy_n(tail_range, count, range_limit + x);
}

void WinnersBackward(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                     const PathRows& others, int min_disparity, int num_disparities,
                     uint8_t* path_scratch, uint16_t* sum_scratch, const WinnerRows& out,
                     uint16_t* right_lane, uint16_t* scratch, const LaneSpan* spans)
{
    // At most 4 (sgm_kernels.hpp): the summed paths and a tag fit 16 bits.
    WithCount<4>(others.count, [&](auto count) {
        const auto with = [&](auto spanned, auto whole) {
            WinnersBackwardOf<count(), spanned(), whole()>(
                cost, p2, p1, width, lanes, others, min_disparity, num_disparities, path_scratch,
                sum_scratch, out, right_lane, scratch, spans);
        };
        using Yes = std::true_type;
        using No = std::false_type;
        const bool whole = num_disparities == lanes;
        if (spans != nullptr)
            whole ? with(Yes(), Yes()) : with(Yes(), No());
        else
            whole ? with(No(), Yes()) : with(No(), No());
    });
}

void CostCurve(const CensusRows& census, int x, int width, int first_disparity, int count,
               uint16_t* curve)
{
    const D8 d;
    const int n = static_cast<int>(hn::Lanes(d));
    // right pixel x - first_disparity - k sits at right_reversed index j0 + k.
    const std::ptrdiff_t j0 = width - 1 - x + first_disparity;
    uint8_t left[8];
    for (int p = 0; p < census.planes; ++p)
        left[p] = census.left[p][x];
    // Byte sums (at most 64 bits differ) a vector at a time, widened into the curve by a
    // loop the compiler vectorises.
    HWY_ALIGN uint8_t sums[kLaneAlign];
    for (int k0 = 0; k0 < count; k0 += n) {
        auto sum = hn::Zero(d);
        for (int p = 0; p < census.planes; ++p) {
            const auto r = hn::LoadU(d, census.right_reversed[p] + j0 + k0);
            sum = hn::Add(sum, hn::PopulationCount(hn::Xor(hn::Set(d, left[p]), r)));
        }
        hn::Store(sum, d, sums);
        uint16_t* c = curve + k0;
        for (int i = 0; i < n; ++i)
            c[i] = static_cast<uint16_t>(c[i] + sums[i]);
    }
}

// Each step's P2 out of the table's two halves by byte shuffles, the step clamped to the
// table: the half a step falls in is chosen after both lookups.
void StepPenalties(const uint8_t* a, const uint8_t* b, int n, const uint8_t* by_step, uint8_t* p2)
{
    const D8 d;
    const int lanes = static_cast<int>(hn::Lanes(d));
    const auto low_table = hn::LoadDup128(d, by_step);
    const auto high_table = hn::LoadDup128(d, by_step + 16);
    const auto last = hn::Set(d, uint8_t{kPenaltySteps - 1});
    const auto sixteen = hn::Set(d, uint8_t{16});
    const auto within = hn::Set(d, uint8_t{15});
    int x = 0;
    for (; x + lanes <= n; x += lanes) {
        const auto va = hn::LoadU(d, a + x), vb = hn::LoadU(d, b + x);
        const auto step = hn::Min(hn::Or(hn::SaturatedSub(va, vb), hn::SaturatedSub(vb, va)), last);
        const auto index = hn::And(step, within);
        hn::StoreU(hn::IfThenElse(hn::Lt(step, sixteen), hn::TableLookupBytes(low_table, index),
                                  hn::TableLookupBytes(high_table, index)),
                   d, p2 + x);
    }
    scalarKernels().step_penalties(a + x, b + x, n - x, by_step, p2 + x);
}

void MedianRow(const int16_t* up, const int16_t* row, const int16_t* down, int width,
               int16_t invalid, int16_t* dst)
{
    const hn::CappedTag<int16_t, 16> d;
    const int n = static_cast<int>(hn::Lanes(d));
    const auto v_invalid = hn::Set(d, invalid);
    const auto sort2 = [](hn::Vec<decltype(d)>& a, hn::Vec<decltype(d)>& b) {
        const auto lo = hn::Min(a, b);
        b = hn::Max(a, b);
        a = lo;
    };
    int x = 1;
    for (; x + n <= width - 1; x += n) {
        const auto c = hn::LoadU(d, row + x);
        const auto pick = [&](const int16_t* at) {
            const auto v = hn::LoadU(d, at);
            return hn::IfThenElse(hn::Eq(v, v_invalid), c, v);
        };
        // Nine named vectors: scalable vector types cannot form arrays.
        auto p0 = pick(up + x - 1), p1 = pick(up + x), p2 = pick(up + x + 1);
        auto p3 = pick(row + x - 1), p4 = c, p5 = pick(row + x + 1);
        auto p6 = pick(down + x - 1), p7 = pick(down + x), p8 = pick(down + x + 1);
        // Paeth's median-of-9 network, as in the scalar reference.
        sort2(p1, p2);
        sort2(p4, p5);
        sort2(p7, p8);
        sort2(p0, p1);
        sort2(p3, p4);
        sort2(p6, p7);
        sort2(p1, p2);
        sort2(p4, p5);
        sort2(p7, p8);
        sort2(p0, p3);
        sort2(p5, p8);
        sort2(p4, p7);
        sort2(p3, p6);
        sort2(p1, p4);
        sort2(p2, p5);
        sort2(p4, p7);
        sort2(p4, p2);
        sort2(p6, p4);
        sort2(p4, p2);
        hn::StoreU(hn::IfThenElse(hn::Eq(c, v_invalid), c, p4), d, dst + x);
    }
    if (x < width - 1) { // the tail: the reference on the last pixels
        scalarKernels().median_row(up + x - 1, row + x - 1, down + x - 1, width - x + 1, invalid,
                                   dst + x - 1);
    }
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
HWY_EXPORT(PathsForward);
HWY_EXPORT(WinnersBackward);
HWY_EXPORT(DecideRow);
HWY_EXPORT(CostCurve);
HWY_EXPORT(StepPenalties);
HWY_EXPORT(MedianRow);
HWY_EXPORT(TargetName);

namespace {

// The kernels of the target Highway has chosen.
SgmKernels chosenKernels()
{
    return SgmKernels{HWY_DYNAMIC_DISPATCH(TargetName)(),    HWY_DYNAMIC_DISPATCH(CensusRow),
                      HWY_DYNAMIC_DISPATCH(CostRow),         HWY_DYNAMIC_DISPATCH(PathsForward),
                      HWY_DYNAMIC_DISPATCH(WinnersBackward), HWY_DYNAMIC_DISPATCH(DecideRow),
                      HWY_DYNAMIC_DISPATCH(CostCurve),       HWY_DYNAMIC_DISPATCH(StepPenalties),
                      HWY_DYNAMIC_DISPATCH(MedianRow)};
}

} // namespace

const SgmKernels& simdKernels()
{
    return chosenTable(chosenKernels);
}

std::vector<SgmKernels> simdKernelsOfEveryTarget()
{
    return tablesOfEveryTarget(chosenKernels);
}

} // namespace stereod::sgm
#endif
