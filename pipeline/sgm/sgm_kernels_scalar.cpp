// The scalar reference of the SGM kernels: plain loops, written for clarity. The SIMD
// kernels must give exactly these integers.

#include <algorithm>
#include <bit>
#include <cstddef>

#include "pipeline/sgm/sgm_kernels.hpp"

namespace stereod::sgm {
namespace {

uint8_t addSaturated(uint8_t a, uint8_t b)
{
    return static_cast<uint8_t>(std::min(255, a + b));
}

void censusRow(const uint8_t* center, size_t stride, int width, int census_width,
               int census_height, uint8_t* const* planes)
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
            const uint8_t* neighbour = center + static_cast<std::ptrdiff_t>(dy) *
                                                    static_cast<std::ptrdiff_t>(stride) + dx;
            uint8_t* plane = planes[bit / 8];
            const int shift = bit % 8;
            for (int x = 0; x < width; ++x)
                if (neighbour[x] < center[x])
                    plane[x] = static_cast<uint8_t>(plane[x] | (1u << shift));
            ++bit;
        }
}

void costRow(const CensusRows& census, int width, int min_disparity, int num_disparities,
             int lanes, uint8_t cost_invalid, uint8_t* cost)
{
    for (int x = 0; x < width; ++x) {
        uint8_t* c = cost + static_cast<size_t>(x) * lanes;
        for (int k = 0; k < lanes; ++k) {
            const int xr = x - (min_disparity + k);
            if (k >= num_disparities || xr < 0 || xr >= width) {
                c[k] = cost_invalid;
                continue;
            }
            int distance = 0;
            for (int p = 0; p < census.planes; ++p)
                distance += std::popcount(
                    static_cast<unsigned>(census.left[p][x] ^ census.right[p][xr]));
            c[k] = static_cast<uint8_t>(distance);
        }
    }
}

// One step of a path: L(k) = C(k) + min(Lp(k), Lp(k±1) + P1, min Lp + P2) - min Lp.
// prev and out are path blocks (L at kPathPad, 255 around it); prev == nullptr starts
// the path (L = C).
void step(const uint8_t* cost, const uint8_t* prev, uint8_t p1, uint8_t p2, int lanes,
          uint8_t* out)
{
    uint8_t* l = out + kPathPad;
    if (prev == nullptr) {
        std::copy(cost, cost + lanes, l);
        return;
    }
    const uint8_t* lp = prev + kPathPad;
    uint8_t min_prev = 255;
    for (int k = 0; k < lanes; ++k)
        min_prev = std::min(min_prev, lp[k]);
    const uint8_t jump = addSaturated(min_prev, p2);
    for (int k = 0; k < lanes; ++k) {
        const uint8_t best = std::min({lp[k], addSaturated(lp[k - 1], p1),
                                       addSaturated(lp[k + 1], p1), jump});
        l[k] = addSaturated(cost[k], static_cast<uint8_t>(best - min_prev));
    }
}

void accumulate(const uint8_t* block, int lanes, bool first, uint16_t* sum)
{
    const uint8_t* l = block + kPathPad;
    for (int k = 0; k < lanes; ++k)
        sum[k] = static_cast<uint16_t>(first ? l[k] : sum[k] + l[k]);
}

void clearPads(uint8_t* block, int lanes)
{
    std::fill(block, block + kPathPad, 255);
    std::fill(block + kPathPad + lanes, block + 2 * kPathPad + lanes, 255);
}

void pathAlongRow(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                  bool forward, bool first, uint8_t* scratch, uint16_t* sum)
{
    const size_t block = pathBlockBytes(lanes);
    uint8_t* a = scratch;
    uint8_t* b = scratch + block;
    clearPads(a, lanes);
    clearPads(b, lanes);
    const uint8_t* prev = nullptr;
    for (int i = 0; i < width; ++i) {
        const int x = forward ? i : width - 1 - i;
        const size_t at = static_cast<size_t>(x) * lanes;
        step(cost + at, prev, p1, p2[x], lanes, a);
        accumulate(a, lanes, first, sum + at);
        prev = a;
        std::swap(a, b);
    }
}

void pathFromAbove(const uint8_t* cost, const uint8_t* p2, uint8_t p1, int width, int lanes,
                   int dx, bool first, const uint8_t* prev, uint8_t* cur, uint16_t* sum)
{
    const size_t block = pathBlockBytes(lanes);
    for (int x = 0; x < width; ++x) {
        const int xp = x + dx;
        const uint8_t* from =
            (prev != nullptr && xp >= 0 && xp < width) ? prev + static_cast<size_t>(xp) * block
                                                       : nullptr;
        uint8_t* out = cur + static_cast<size_t>(x) * block;
        clearPads(out, lanes);
        const size_t at = static_cast<size_t>(x) * lanes;
        step(cost + at, from, p1, p2[x], lanes, out);
        accumulate(out, lanes, first, sum + at);
    }
}

void winners(const uint16_t* sum, int width, int min_disparity, int num_disparities,
             int lanes, Winner* out, uint32_t* right_best, uint32_t* /*scratch*/)
{
    std::fill(right_best, right_best + width, 0xFFFFFFFFu);
    for (int x = 0; x < width; ++x) {
        const uint16_t* s = sum + static_cast<size_t>(x) * lanes;
        int best = 0;
        for (int k = 1; k < num_disparities; ++k)
            if (s[k] < s[best])
                best = k;
        uint16_t second = 0xFFFF;
        for (int k = 0; k < num_disparities; ++k)
            if (k < best - 1 || k > best + 1)
                second = std::min(second, s[k]);
        out[x] = Winner{static_cast<uint16_t>(best), s[best], second};
        for (int k = 0; k < num_disparities; ++k) {
            const int xr = x - min_disparity - k;
            if (xr < 0 || xr >= width)
                continue;
            const uint32_t packed = (static_cast<uint32_t>(s[k]) << 16) | static_cast<uint32_t>(k);
            right_best[xr] = std::min(right_best[xr], packed);
        }
    }
}

} // namespace

const SgmKernels& scalarKernels()
{
    static const SgmKernels kernels{"scalar", censusRow, costRow, pathAlongRow, pathFromAbove, winners};
    return kernels;
}

} // namespace stereod::sgm
