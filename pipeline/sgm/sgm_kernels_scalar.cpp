// The scalar reference of the SGM kernels: plain loops, written for clarity. The SIMD
// kernels must give exactly these integers.

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdlib>

#include "pipeline/sgm/sgm_kernels.hpp"

namespace stereod::sgm {
namespace {

uint8_t addSaturated(uint8_t a, uint8_t b)
{
    return static_cast<uint8_t>(std::min(255, a + b));
}

void censusRow(const uint8_t* center, size_t stride, int width, int census_width, int census_height,
               uint8_t* const* planes)
{
    const int rx = census_width / 2;
    const int ry = census_height / 2;
    const int bits = census_width * census_height - 1;
    for (int p = 0; p < (bits + 7) / 8; ++p)
        std::fill(planes[p], planes[p] + width, 0);
    int bit = 0;
    for (int dy = -ry; dy <= ry; ++dy)
        for (int dx = -rx; dx <= rx; ++dx) {
            if (dy == 0 && dx == 0)
                continue;
            const uint8_t* neighbour =
                center + static_cast<std::ptrdiff_t>(dy) * static_cast<std::ptrdiff_t>(stride) + dx;
            uint8_t* plane = planes[bit / 8];
            const int shift = bit % 8;
            for (int x = 0; x < width; ++x)
                if (neighbour[x] < center[x])
                    plane[x] = static_cast<uint8_t>(plane[x] | (1u << shift));
            ++bit;
        }
}

void costRow(const CensusRows& census, int width, int min_disparity, int num_disparities, int lanes,
             uint8_t cost_invalid, uint8_t* cost, const LaneSpan* spans)
{
    for (int x = 0; x < width; ++x) {
        uint8_t* c = cost + static_cast<size_t>(x) * lanes;
        const LaneInterval span = lanesOf(spans, x, lanes);
        for (int k = span.first; k < span.end; ++k) {
            const int xr = x - (min_disparity + k);
            if (k >= num_disparities || xr < 0 || xr >= width) {
                c[k] = cost_invalid;
                continue;
            }
            int distance = 0;
            for (int p = 0; p < census.planes; ++p)
                distance +=
                    std::popcount(static_cast<unsigned>(census.left[p][x] ^ census.right[p][xr]));
            c[k] = static_cast<uint8_t>(distance);
        }
    }
}

void costCurve(const CensusRows& census, int x, int width, int first_disparity, int count,
               uint16_t* curve)
{
    (void)width;
    for (int k = 0; k < count; ++k) {
        const int xr = x - first_disparity - k;
        int distance = 0;
        for (int p = 0; p < census.planes; ++p)
            distance +=
                std::popcount(static_cast<unsigned>(census.left[p][x] ^ census.right[p][xr]));
        curve[k] = static_cast<uint16_t>(curve[k] + distance);
    }
}

// One step of a path: L(k) = C(k) + min(Lp(k), Lp(k±1) + P1, min Lp + P2) - min Lp, for
// the lanes of `span`; L is 255 at the others. prev and out are path blocks (L at
// kPathPad, 255 around it), prev holding 255 outside its own span; prev == nullptr starts
// the path (L = C).
void step(const uint8_t* cost, const uint8_t* prev, uint8_t p1, uint8_t p2, int lanes,
          LaneInterval span, uint8_t* out)
{
    uint8_t* l = out + kPathPad;
    std::fill(l, l + span.first, uint8_t{255});
    std::fill(l + span.end, l + lanes, uint8_t{255});
    if (prev == nullptr) {
        std::copy(cost + span.first, cost + span.end, l + span.first);
        return;
    }
    const uint8_t* lp = prev + kPathPad;
    uint8_t min_prev = 255;
    for (int k = 0; k < lanes; ++k)
        min_prev = std::min(min_prev, lp[k]);
    const uint8_t jump = addSaturated(min_prev, p2);
    for (int k = span.first; k < span.end; ++k) {
        const uint8_t best =
            std::min({lp[k], addSaturated(lp[k - 1], p1), addSaturated(lp[k + 1], p1), jump});
        l[k] = addSaturated(cost[k], static_cast<uint8_t>(best - min_prev));
    }
}

void pathForward(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                 const LaneSpan* spans, uint8_t* out)
{
    const size_t block = pathBlockBytes(lanes);
    const uint8_t* prev = nullptr;
    for (int x = 0; x < width; ++x) {
        uint8_t* l = out + static_cast<size_t>(x) * block;
        step(cost + static_cast<size_t>(x) * static_cast<size_t>(lanes), prev, p1, p2[x], lanes,
             lanesOf(spans, x, lanes), l);
        prev = l;
    }
}

void pathFromAbove(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes, int dx,
                   const LaneSpan* spans, const uint8_t* prev, uint8_t* cur)
{
    const size_t block = pathBlockBytes(lanes);
    for (int x = 0; x < width; ++x) {
        const int xp = x + dx;
        const uint8_t* from = (prev != nullptr && xp >= 0 && xp < width)
                                  ? prev + static_cast<size_t>(xp) * block
                                  : nullptr;
        step(cost + static_cast<size_t>(x) * static_cast<size_t>(lanes), from, p1, p2[x], lanes,
             lanesOf(spans, x, lanes), cur + static_cast<size_t>(x) * block);
    }
}

void pathsForward(const uint8_t* cost, uint8_t p1, int width, int lanes, const AbovePaths& above,
                  const uint8_t* p2_along, uint8_t* along, const LaneSpan* spans)
{
    for (int i = 0; i < above.count; ++i)
        pathFromAbove(cost, above.p2[i], p1, width, lanes, above.dx[i], spans, above.prev[i],
                      above.cur[i]);
    if (along != nullptr)
        pathForward(cost, p2_along, p1, width, lanes, spans, along);
}

void winnersBackward(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                     const PathRows& others, int min_disparity, int num_disparities,
                     uint8_t* path_scratch, uint16_t* s, const WinnerRows& out,
                     uint16_t* right_lane, uint16_t* scratch, const LaneSpan* spans)
{
    const size_t block = pathBlockBytes(lanes);
    uint8_t* a = path_scratch;
    uint8_t* b = path_scratch + block;
    const uint8_t* prev = nullptr;
    // The right view's best sum per right pixel; its lane goes to right_lane.
    uint16_t* right_sum = scratch;
    std::fill(right_sum, right_sum + width, uint16_t{0xFFFF});
    std::fill(right_lane, right_lane + width, uint16_t{0xFFFF});
    for (int x = width - 1; x >= 0; --x) {
        const size_t at = static_cast<size_t>(x) * static_cast<size_t>(lanes);
        const LaneInterval span = lanesOf(spans, x, lanes);
        step(cost + at, prev, p1, p2[x], lanes, span, a);
        // The summed lanes: the span's, within the range.
        const int first = span.first;
        const int end = std::min(span.end, num_disparities);
        for (int k = first; k < end; ++k) {
            int total = a[kPathPad + k];
            for (int i = 0; i < others.count; ++i)
                total += others.rows[i][static_cast<size_t>(x) * block + kPathPad +
                                        static_cast<size_t>(k)];
            s[k] = static_cast<uint16_t>(total);
        }
        prev = a;
        std::swap(a, b);

        int best = first;
        for (int k = first + 1; k < end; ++k)
            if (s[k] < s[best])
                best = k;
        uint16_t second = 0xFFFF;
        for (int k = first; k < end; ++k)
            if (k < best - 1 || k > best + 1)
                second = std::min(second, s[k]);
        // A minimum at an end of the span that is not an end of the range: the true one
        // may lie beyond it.
        if ((best == first && first > 0) || (best == end - 1 && end < num_disparities))
            second = s[best];
        const uint16_t below = best > first ? s[best - 1] : uint16_t{0};
        const uint16_t above = best < end - 1 ? s[best + 1] : uint16_t{0};
        out.best_lane[x] = static_cast<uint16_t>(best);
        out.best_sum[x] = s[best];
        out.second_sum[x] = second;
        out.below_sum[x] = below;
        out.above_sum[x] = above;
        for (int k = first; k < end; ++k) {
            const int xr = x - min_disparity - k;
            if (xr < 0 || xr >= width)
                continue;
            if (s[k] < right_sum[xr] || (s[k] == right_sum[xr] && k < right_lane[xr])) {
                right_sum[xr] = s[k];
                right_lane[xr] = static_cast<uint16_t>(k);
            }
        }
    }
}

// 1..255 from the three signs of a trustworthy match: how much better the best sum is
// than the best non-adjacent one, how sharp the minimum is (curvature: the sums at best
// -1 and +1 less twice the best; 0 where there is no parabola), and whether the right view
// agrees exactly (lr_diff: 0, 1, or 2 for more); scaled down where the left edge cut the
// search to searchable + 1 of the lanes. Single-precision operations in a fixed order,
// which the SIMD kernel repeats lane by lane (the library compiles with
// -ffp-contract=off, so that no compiler fuses them differently).
uint8_t confidenceOf(uint32_t best, uint32_t second, int curvature, int lr_diff, int searchable,
                     const DecideSettings& s)
{
    // uniqueness = min(1, margin / 0.5), margin = (second - best) / max(1, best); with no
    // second (0xFFFF) the margin is far above 0.5, as sums stay within 5 x 255.
    const float uniqueness =
        std::min(1.0f, static_cast<float>(2 * static_cast<int>(second - best)) /
                           static_cast<float>(best > 0 ? best : 1u));
    const float sharpness = std::min(1.0f, static_cast<float>(curvature) / s.sharp_curvature);
    const float agreement = lr_diff == 0 ? 1.0f : lr_diff == 1 ? 0.7f : 0.4f;
    const float reach = static_cast<float>(searchable + 1) / static_cast<float>(s.num_disparities);
    const float c = 255.0f * uniqueness * (0.5f + 0.5f * sharpness) * agreement * reach;
    return static_cast<uint8_t>(std::clamp(static_cast<int>(c + 0.5f), 1, 255)); // c >= 0
}

void decideRow(const WinnerRows& w, const uint16_t* right_lane, int width, const DecideSettings& s,
               int16_t* disparity, uint8_t* confidence, uint8_t* range_limit)
{
    const int n = s.num_disparities;
    for (int x = 0; x < width; ++x) {
        disparity[x] = kNoDisparity;
        confidence[x] = 0;
        range_limit[x] = 0;
        const int k = w.best_lane[x];
        // The lanes this pixel could search: its right pixel x - d must be in the image.
        const int searchable = std::min(n - 1, x - s.min_disparity);
        if (searchable < 0)
            continue;
        if (searchable == n - 1 && k == n - 1) {
            // The best match at the near end of the range: the surface may be nearer than
            // the range sees, and no number from the edge is trustworthy.
            range_limit[x] = 1;
            continue;
        }
        if (searchable < n - 1 && k > searchable - s.edge_margin_px)
            continue; // its true match may lie beyond the left edge of the right image
        const uint32_t best = w.best_sum[x];
        const uint32_t second = w.second_sum[x];
        if (second * 100u <= best * static_cast<uint32_t>(100 + s.uniqueness_percent))
            continue;
        int lr_diff = 0;
        if (s.lr_max_diff_px >= 0) {
            // A lane whose right pixel is outside the row has no right view to agree.
            const int xr = x - s.min_disparity - k;
            const uint16_t right = xr >= 0 && xr < width ? right_lane[xr] : uint16_t{0xFFFF};
            if (right == 0xFFFF)
                continue;
            lr_diff = std::abs(static_cast<int>(right) - k);
            if (lr_diff > s.lr_max_diff_px)
                continue;
        }
        int offset16 = 0;
        int curvature = 0;
        // The parabola needs both neighbours searched: not at either end of the range, nor
        // at the last lane the left image edge lets this pixel search.
        if (k > 0 && k < std::min(n - 1, searchable)) {
            const int below = w.below_sum[x];
            const int above = w.above_sum[x];
            curvature = below + above - 2 * static_cast<int>(best); // >= 0: best is smallest
            if (curvature > 0) {
                // Rounded half away from zero: (below - above) / (2 curvature) * 16.
                const int numerator = (below - above) * kSubpixel;
                offset16 = (numerator >= 0 ? numerator + curvature : numerator - curvature) /
                           (2 * curvature);
            }
        }
        disparity[x] = static_cast<int16_t>((s.min_disparity + k) * kSubpixel + offset16);
        confidence[x] = confidenceOf(best, second, curvature, std::min(lr_diff, 2), searchable, s);
    }
}

void medianRow(const int16_t* up, const int16_t* row, const int16_t* down, int width,
               int16_t invalid, int16_t* dst)
{
    const auto sort2 = [](int16_t& a, int16_t& b) {
        const int16_t lo = std::min(a, b);
        b = std::max(a, b);
        a = lo;
    };
    for (int x = 1; x < width - 1; ++x) {
        const int16_t c = row[x];
        if (c == invalid) {
            dst[x] = invalid;
            continue;
        }
        const auto pick = [c, invalid](int16_t v) { return v == invalid ? c : v; };
        int16_t p[9] = {pick(up[x - 1]),  pick(up[x]),       pick(up[x + 1]), pick(row[x - 1]), c,
                        pick(row[x + 1]), pick(down[x - 1]), pick(down[x]),   pick(down[x + 1])};
        // Paeth's median-of-9 network: 19 compare-exchanges.
        sort2(p[1], p[2]);
        sort2(p[4], p[5]);
        sort2(p[7], p[8]);
        sort2(p[0], p[1]);
        sort2(p[3], p[4]);
        sort2(p[6], p[7]);
        sort2(p[1], p[2]);
        sort2(p[4], p[5]);
        sort2(p[7], p[8]);
        sort2(p[0], p[3]);
        sort2(p[5], p[8]);
        sort2(p[4], p[7]);
        sort2(p[3], p[6]);
        sort2(p[1], p[4]);
        sort2(p[2], p[5]);
        sort2(p[4], p[7]);
        sort2(p[4], p[2]);
        sort2(p[6], p[4]);
        sort2(p[4], p[2]);
        dst[x] = p[4];
    }
}

void stepPenalties(const uint8_t* a, const uint8_t* b, int n, const uint8_t* by_step, uint8_t* p2)
{
    for (int x = 0; x < n; ++x)
        p2[x] = by_step[std::min(std::abs(static_cast<int>(a[x]) - static_cast<int>(b[x])),
                                 kPenaltySteps - 1)];
}

} // namespace

const SgmKernels& scalarKernels()
{
    static const SgmKernels kernels{"scalar",     censusRow,       costRow,
                                    pathsForward, winnersBackward, decideRow,
                                    costCurve,    stepPenalties,   medianRow};
    return kernels;
}

} // namespace stereod::sgm
