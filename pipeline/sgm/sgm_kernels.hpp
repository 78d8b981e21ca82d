#pragma once
// The inner loops of census semi-global matching, one image row at a time, in two
// implementations with one contract: a plain scalar reference and a SIMD one (Highway,
// dispatched at run time to the best target the processor has: AVX2, SSE4, NEON, ...).
// Both compute exactly the same integers; tests hold them to it.
//
// Units and layouts shared by every kernel:
//  - disparities are searched as k = 0 .. lanes-1, meaning d = min_disparity + k; `lanes`
//    is the number of disparities rounded up to a multiple of kLaneAlign, and the padding
//    lanes carry the largest census cost so that they never win;
//  - a cost row holds, for each pixel x, `lanes` bytes: the Hamming distance between the
//    census of left pixel x and right pixel x - d (cost_invalid where x - d is outside the
//    image);
//  - a path row holds, for each pixel, a block of `lanes + 2 * kPathPad` bytes: the path
//    cost L at [kPathPad, kPathPad + lanes) and 255 in the bytes just before and after,
//    so that L[k - 1] and L[k + 1] can be loaded without a branch at either end;
//  - path costs are 8-bit: L(p, k) = C(p, k) + min(L(p-r, k), L(p-r, k±1) + P1,
//    min L(p-r) + P2) - min L(p-r), which stays within max cost + P2 <= 255 (the settings
//    make sure of it), and each addition saturates;
//  - the pads of a path block are set to 255 once, when its buffer is allocated: kernels
//    write only the L bytes and byte 0, where the SIMD kernels keep min L of the block
//    for the next step of the path (the scalar reference leaves it alone);
//  - the sum of the paths is 16-bit and is formed only inside winners_backward(), from
//    the 8-bit rows of the other paths and its own: no 16-bit sum row is ever kept;
//  - with lane spans (a guided search, pyramid_sgm.hpp), pixel x searches only the lanes
//    of spans[x]: its costs and path costs are computed there alone, a path cost outside
//    a pixel's span counts as 255 (never reached) for the next pixel of the path, and its
//    winner is the best inside the span. A path block then holds its span's L, and 255
//    in the kLaneAlign bytes just before and after the span (its guards: they stand in
//    for the lanes beyond, so that L[k - 1] and L[k + 1] load without a branch); the
//    bytes further out keep whatever an earlier pixel left there and are never read.
//
// Reentrant: kernels keep no state; each thread passes its own rows.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace stereod::sgm {

inline constexpr int kLaneAlign = 32; // one AVX2 vector of bytes
inline constexpr int kPathPad = 32;   // keeps each path block's L values aligned

inline constexpr size_t pathBlockBytes(int lanes)
{
    return static_cast<size_t>(lanes + 2 * kPathPad);
}

// The lanes one pixel searches, in units of kLaneAlign: k in [kLaneAlign * first,
// kLaneAlign * end), first < end <= lanes / kLaneAlign. The kernels take one per pixel of
// a row, or nullptr: every lane.
struct LaneSpan {
    uint8_t first = 0;
    uint8_t end = 0;
};

// The lanes [first, end) pixel x searches: those of spans[x], or every lane.
struct LaneInterval {
    int first = 0;
    int end = 0;
};
inline LaneInterval lanesOf(const LaneSpan* spans, int x, int lanes)
{
    if (spans == nullptr)
        return {0, lanes};
    return {kLaneAlign * spans[x].first, kLaneAlign * spans[x].end};
}

// One row of the census images of both views: `planes` byte planes, plane p holding
// bits 8p .. 8p+7 of every pixel's census.
struct CensusRows {
    const uint8_t* const* left; // [planes] pointers to `width` bytes
    const uint8_t* const* right;
    // The right row backwards: right_reversed[p][j] = right[p][width - 1 - j]. Bytes from
    // min_disparity - 1 to width + min_disparity + lanes around it must be readable
    // (their values do not matter).
    const uint8_t* const* right_reversed;
    int planes = 0;
};

// Entries of scratch that winners_backward() needs for a row: the right view's best sum
// and lane per right pixel, with margins for the lanes that fall outside the row.
inline constexpr size_t winnersScratch(int width, int min_disparity, int lanes)
{
    return 2 * (static_cast<size_t>(width) +
                2 * static_cast<size_t>(
                        lanes + (min_disparity < 0 ? -min_disparity : min_disparity) + kLaneAlign));
}

// Entries of sum_scratch that winners_backward() needs: the summed paths of 16 pixels,
// each with 16 entries of margin on both sides, and two vectors per pixel.
inline constexpr int kWinnerGroup = 16;
inline constexpr size_t winnersSumScratch(int lanes)
{
    return static_cast<size_t>(kWinnerGroup) * static_cast<size_t>(lanes + 32 + kLaneAlign);
}

// The best and second-best disparity lane of each pixel of a row over the summed paths,
// a row of `width` entries per field, so that decide_row() loads them as vectors.
struct WinnerRows {
    uint16_t* best_lane; // smallest k with the smallest sum (ties: smallest k)
    uint16_t* best_sum;
    uint16_t* second_sum; // smallest sum with |k - best_lane| > 1 (0xFFFF if none)
    uint16_t* below_sum;  // the sums at best_lane - 1 and + 1, for sub-pixel
    uint16_t* above_sum;  // interpolation (0 outside 0 .. num_disparities - 1)
};

// Entries right_lane needs: one past the row, which decide_row() may read (and ignore).
inline constexpr size_t rightLaneEntries(int width)
{
    return static_cast<size_t>(width) + 1;
}

// What decide_row() needs of the matcher's settings.
struct DecideSettings {
    int min_disparity = 0;
    int num_disparities = 0;
    int uniqueness_percent = 0; // the best non-adjacent sum must exceed the best by this
    int lr_max_diff_px = 0;     // < 0: no left-right check
    int edge_margin_px = 0;     // lanes kept clear of the last one the left edge allows
    float sharp_curvature = 1;  // the curvature of a fully sharp minimum: 2 p1 paths
};

// The intensity steps step_penalties() tells apart (two 16-byte table lookups).
inline constexpr int kPenaltySteps = 32;

// Disparities leave decide_row() in fixed point, 16 x pixels, kNoDisparity where none.
inline constexpr int kSubpixel = 16;
inline constexpr int16_t kNoDisparity = -32768;

// The paths from the previous row onto row y: path i steps from (x + dx[i], y - 1) onto
// (x, y), dx in -1..1, count <= 3.
struct AbovePaths {
    int count = 0;
    const int* dx;
    const uint8_t* const* p2;   // [count] rows: P2 of the step onto x
    const uint8_t* const* prev; // [count] row y-1's path blocks, or nullptr on the path's
                                // first row (then L = C)
    uint8_t* const* cur;        // [count] row y's path blocks, written
    // Row y-1's lane spans, when the kernel is given spans for row y (the same image's).
    const LaneSpan* prev_spans = nullptr;
};

// The rows that winners_backward() sums with its own path: `count` rows of `width` path
// blocks each (the paths from above, and the left->right path). count <= 4, so that a
// sum stays within 5 x 255 (the SIMD kernels pack a sum and a lane tag in 16 bits).
struct PathRows {
    const uint8_t* const* rows;
    int count = 0;
};

struct SgmKernels {
    const char* target; // "scalar", "AVX2", "SSE4", "NEON", ...

    // The census of one row: for each pixel x, bit i of its census is set when the i-th
    // neighbour of the window (raster order, the centre skipped) is darker than the
    // centre. center points at pixel 0 of the row in an image padded by census_width / 2
    // columns and census_height / 2 rows on every side; planes[p] receives byte p.
    void (*census_row)(const uint8_t* center, size_t stride, int width, int census_width,
                       int census_height, uint8_t* const* planes);

    // cost[x * lanes + k] for x in 0..width-1: Hamming distance of the censuses; lanes
    // whose right pixel x - (min_disparity + k) lies outside 0..width-1, and lanes at or
    // past num_disparities, get cost_invalid. With spans, only the lanes of spans[x].
    void (*cost_row)(const CensusRows& census, int width, int min_disparity, int num_disparities,
                     int lanes, uint8_t cost_invalid, uint8_t* cost, const LaneSpan* spans);

    // The paths that come from the previous row, and the left->right path along the row,
    // in one pass over the row (the path along the row waits on each pixel's min L; the
    // others fill that time). Writes every pixel's path block of each path from above to
    // above.cur[i] and, unless `along` is nullptr, of the left->right path to along
    // (width blocks each). p2_along[x]: P2 for the step from x - 1 onto x. With spans
    // (row y's; above.prev_spans row y-1's), each pixel's lanes alone (see above).
    void (*paths_forward)(const uint8_t* cost, uint8_t p1, int width, int lanes,
                          const AbovePaths& above, const uint8_t* p2_along, uint8_t* along,
                          const LaneSpan* spans);

    // The right->left path along the row (p2[x]: stepping onto x), summed in 16 bits with
    // `others`, and the winner of every pixel over the first num_disparities lanes (a
    // multiple of 16); and, for the right view, right_lane[xr] = the lane k with the
    // smallest sum (ties: smallest k) among the lanes whose left pixel
    // xr + min_disparity + k lies inside the row (0xFFFF when none). path_scratch: two path
    // blocks (pads 255); sum_scratch: winnersSumScratch() entries; scratch:
    // winnersScratch() entries. With spans, each pixel's winner, second and neighbours'
    // sums come from the lanes of its span (0 for a neighbour outside it), and only those
    // lanes offer the right view a match; a best lane at an end of the span that is not an
    // end of the range (the true minimum may lie beyond it) gets second_sum = best_sum,
    // which no uniqueness test passes.
    void (*winners_backward)(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width,
                             int lanes, const PathRows& others, int min_disparity,
                             int num_disparities, uint8_t* path_scratch, uint16_t* sum_scratch,
                             const WinnerRows& winners, uint16_t* right_lane, uint16_t* scratch,
                             const LaneSpan* spans);

    // The winners of a row made into what the matcher reports, for x in 0..width-1:
    //  - disparity[x]: 16 x (min_disparity + best lane + the parabola's sub-pixel offset
    //    through the sums at best -1, best, best +1, rounded half away from zero), or
    //    kNoDisparity when the pixel searched nothing, when its best lane is the range's
    //    near end, when the left image edge cut its search within edge_margin_px of its
    //    best lane, when the best non-adjacent sum is within uniqueness_percent of the
    //    best, or when the right view's lane (right_lane[x - d], rightLaneEntries()
    //    readable) differs by more than lr_max_diff_px;
    //  - confidence[x]: 0 without a disparity, else 1..255 from the uniqueness margin,
    //    the curvature of the minimum and the left-right agreement (confidenceOf() in the
    //    scalar reference: single-precision operations in an order both implementations
    //    keep, with no fused multiply-add);
    //  - range_limit[x]: 1 when the best lane is the range's near end, with the whole range
    //    searched (the surface may be nearer than the range sees), else 0.
    void (*decide_row)(const WinnerRows& winners, const uint16_t* right_lane, int width,
                       const DecideSettings& settings, int16_t* disparity, uint8_t* confidence,
                       uint8_t* range_limit);

    // Adds one pixel's matching costs to a cost curve over a run of disparities: for k in
    // 0..count-1, curve[k] += the Hamming distance of the census of left pixel x and right
    // pixel x - (first_disparity + k). The caller keeps every right pixel inside the row
    // (0 <= x - first_disparity - (count - 1) and x - first_disparity <= width - 1), gives
    // a curve of count entries rounded up to a multiple of kLaneAlign, and ignores the
    // entries past count (they may change). right_reversed is read up to kLaneAlign bytes
    // past the run. For the near-field probe (near_field_probe.hpp), which compares the
    // costs of whole tiles within and beyond the range a matcher searched.
    void (*cost_curve)(const CensusRows& census, int x, int width, int first_disparity, int count,
                       uint16_t* curve);

    // P2 of the steps between two rows of grey levels: p2[x] = by_step[min(|a[x] - b[x]|,
    // kPenaltySteps - 1)] for x in 0..n-1. by_step holds kPenaltySteps entries: a table of
    // P2 by intensity step that keeps its last value for every larger step.
    void (*step_penalties)(const uint8_t* a, const uint8_t* b, int n, const uint8_t* by_step,
                           uint8_t* p2);

    // One row of the 3x3 median of 16-bit disparities (up, row, down: rows y-1, y, y+1),
    // for x in 1 .. width-2: `invalid` stays invalid, and an invalid neighbour counts as
    // the centre's value. dst[0] and dst[width-1] are left alone.
    void (*median_row)(const int16_t* up, const int16_t* row, const int16_t* down, int width,
                       int16_t invalid, int16_t* dst);
};

const SgmKernels& scalarKernels();
// The SIMD implementation for the best target this processor supports.
const SgmKernels& simdKernels();
// The SIMD implementation for every target Highway compiled that this processor runs
// (AVX2 and AVX-512 on one x86 machine, say), best last: what the kernel tests hold
// against the scalar reference, so that a target this machine would not pick is tested
// too. Not thread-safe: it switches Highway's chosen target while it collects them (and
// sets it back); simdKernels() is chosen first, so matchers are not affected.
std::vector<SgmKernels> simdKernelsOfEveryTarget();

} // namespace stereod::sgm
