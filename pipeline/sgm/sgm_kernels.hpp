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
//  - the sum of the paths is 16-bit, `lanes` per pixel.
//
// Reentrant: kernels keep no state; each thread passes its own rows.

#include <cstddef>
#include <cstdint>

namespace stereod::sgm {

inline constexpr int kLaneAlign = 32;   // one AVX2 vector of bytes
inline constexpr int kPathPad = 32;     // keeps each path block's L values aligned

inline constexpr size_t pathBlockBytes(int lanes)
{
    return static_cast<size_t>(lanes + 2 * kPathPad);
}

// One row of the census images of both views: `planes` byte planes, plane p holding
// bits 8p .. 8p+7 of every pixel's census.
struct CensusRows {
    const uint8_t* const* left;    // [planes] pointers to `width` bytes
    const uint8_t* const* right;
    // The right row backwards: right_reversed[p][j] = right[p][width - 1 - j]. Bytes from
    // min_disparity - 1 to width + min_disparity + lanes around it must be readable
    // (their values do not matter).
    const uint8_t* const* right_reversed;
    int planes = 0;
};

// Entries of scratch that winners() needs for a row.
inline constexpr size_t winnersScratch(int width, int min_disparity, int lanes)
{
    return static_cast<size_t>(width) + 2 * static_cast<size_t>(lanes + (min_disparity < 0 ? -min_disparity : min_disparity) + kLaneAlign);
}

// The best and second-best disparity lane of one pixel over the summed paths.
struct Winner {
    uint16_t best_lane;            // smallest k with the smallest sum (ties: smallest k)
    uint16_t best_sum;
    uint16_t second_sum;           // smallest sum with |k - best_lane| > 1 (0xFFFF if none)
};

struct SgmKernels {
    const char* target;            // "scalar", "AVX2", "SSE4", "NEON", ...

    // The census of one row: for each pixel x, bit i of its census is set when the i-th
    // neighbour of the window (raster order, the centre skipped) is darker than the
    // centre. center points at pixel 0 of the row in an image padded by census_width / 2
    // columns and census_height / 2 rows on every side; planes[p] receives byte p.
    void (*census_row)(const uint8_t* center, size_t stride, int width, int census_width,
                       int census_height, uint8_t* const* planes);

    // cost[x * lanes + k] for x in 0..width-1: Hamming distance of the censuses; lanes
    // whose right pixel x - (min_disparity + k) lies outside 0..width-1, and lanes at or
    // past num_disparities, get cost_invalid.
    void (*cost_row)(const CensusRows& census, int width, int min_disparity,
                     int num_disparities, int lanes, uint8_t cost_invalid, uint8_t* cost);

    // The path along the row: left to right when `forward`, else right to left.
    // p2[x] is the penalty for a jump of more than one disparity when stepping onto x.
    // Adds the path cost of every pixel into sum (or stores it when `first`); `scratch`
    // holds two path blocks.
    void (*path_along_row)(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width,
                           int lanes, bool forward, bool first, uint8_t* scratch,
                           uint16_t* sum);

    // A path coming from the previous row: from (x + dx, y - 1) onto (x, y), dx in -1..1.
    // prev: the previous row's path blocks for this path, written by the same kernels (a
    // block's pad bytes may carry what the next step needs), or nullptr on the path's
    // first row (then L = C). Writes this row's blocks to cur (same layout) and adds into sum
    // (or stores when `first`).
    void (*path_from_above)(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width,
                            int lanes, int dx, bool first, const uint8_t* prev,
                            uint8_t* cur, uint16_t* sum);

    // Winner of every pixel of the row over the first num_disparities lanes (a multiple
    // of 16); and, for the right view, right_best[xr] = smallest (sum << 16 | k) over the
    // lanes k whose left pixel xr + min_disparity + k lies inside the row (0xFFFFFFFF
    // when none). scratch: winnersScratch() entries.
    void (*winners)(const uint16_t* sum, int width, int min_disparity, int num_disparities,
                    int lanes, Winner* winners, uint32_t* right_best, uint32_t* scratch);
};

const SgmKernels& scalarKernels();
// The SIMD implementation for the best target this processor supports.
const SgmKernels& simdKernels();

} // namespace stereod::sgm
