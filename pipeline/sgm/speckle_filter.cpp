#include "pipeline/sgm/speckle_filter.hpp"

#include <algorithm>
#include <bit>
#include <cstring>
#include <stdexcept>
#include <string>

namespace stereod::sgm {
namespace {

// Two valid neighbours belong to one region when their disparities differ by at most
// max_step: 1 when they do, as one unsigned comparison that vector loops take (a negative
// step joins nothing).
uint8_t together(int a, int b, int max_step)
{
    return static_cast<uint8_t>((max_step >= 0) & (static_cast<uint32_t>(a - b + max_step) <=
                                                   static_cast<uint32_t>(2 * max_step)));
}

constexpr int kMaxWidth = 65535; // run ends are 16-bit

// Pixels of a row whose runs labelBand() finds together, one bit each.
constexpr int kChunk = 64;

// Eight bytes of 0 or 1 as the eight low bits of one byte (byte i to bit i): each byte's
// bit lands in the top byte of the product, and no two products overlap.
uint64_t packBytes(const uint8_t* flags)
{
    uint64_t word;
    std::memcpy(&word, flags, sizeof word);
    return (word * 0x0102040810204080ULL) >> 56;
}

struct ChunkBits {
    uint64_t valid;        // bit i: pixel x0 + i has a disparity
    uint64_t goes_on;      // bit i: ... and belongs together with pixel x0 + i - 1
    uint64_t next_goes_on; // the same for pixel x0 + 64 (0 or 1)
};

// The bits of pixels x0 .. x0 + 63 of row d (pixels past the row: invalid). The row's
// values from x0 - 1 to x0 + 64 are copied first, so that the tests run in loops of fixed
// length with no branch: vector loops.
ChunkBits chunkBits(const int16_t* d, int width, int x0, int16_t invalid, int max_step)
{
    int16_t seg[kChunk + 2];
    const int from = std::max(0, x0 - 1), to = std::min(width, x0 + kChunk + 1);
    std::fill(seg, seg + kChunk + 2, invalid);
    std::copy(d + from, d + to, seg + (from - (x0 - 1)));
    alignas(8) uint8_t valid[kChunk + 8];
    alignas(8) uint8_t goes_on[kChunk + 8];
    for (int i = 0; i < kChunk + 1; ++i) {
        const int a = seg[i + 1], b = seg[i];
        const bool here = a != invalid;
        valid[i] = static_cast<uint8_t>(here);
        goes_on[i] = static_cast<uint8_t>(here & (b != invalid) & together(a, b, max_step));
    }
    ChunkBits bits{0, 0, goes_on[kChunk]};
    for (int byte = 0; byte < kChunk / 8; ++byte) {
        bits.valid |= packBytes(valid + 8 * byte) << (8 * byte);
        bits.goes_on |= packBytes(goes_on + 8 * byte) << (8 * byte);
    }
    return bits;
}

} // namespace

size_t speckleFilterBytes(int width, int height)
{
    const size_t area = static_cast<size_t>(width) * static_cast<size_t>(height);
    return area * (2 * sizeof(uint16_t) + 2 * sizeof(uint32_t)) +
           static_cast<size_t>(height) * sizeof(uint32_t);
}

SpeckleFilter::SpeckleFilter(int width, int height) : width_(width), height_(height)
{
    if (width < 1 || width > kMaxWidth || height < 1)
        throw std::invalid_argument("SpeckleFilter: a " + std::to_string(width) + "x" +
                                    std::to_string(height) + " image (width 1 to " +
                                    std::to_string(kMaxWidth) + ")");
    const size_t area = static_cast<size_t>(width) * static_cast<size_t>(height);
    runs_.assign(static_cast<size_t>(height), 0);
    begin_.assign(area, 0);
    end_.assign(area, 0);
    parent_.assign(area, 0);
    size_.assign(area, 0);
}

void SpeckleFilter::apply(int16_t* disparity, int16_t invalid, int max_step, int max_size)
{
    labelBand(disparity, invalid, max_step, 0, height_);
    removeBand(disparity, invalid, max_size, 0, height_);
}

uint32_t SpeckleFilter::rootHalving(uint32_t region)
{
    while (parent_[region] != region) {
        parent_[region] = parent_[parent_[region]];
        region = parent_[region];
    }
    return region;
}

uint32_t SpeckleFilter::join(uint32_t a, uint32_t b)
{
    // The larger index joins the smaller: the roots stay ordered, the chains short.
    const uint32_t keep = std::min(a, b);
    const uint32_t joined = std::max(a, b);
    parent_[joined] = keep;
    size_[keep] += size_[joined];
    return keep;
}

void SpeckleFilter::labelBand(const int16_t* disparity, int16_t invalid, int max_step, int y0,
                              int y1)
{
    const int w = width_;
    for (int y = y0; y < y1; ++y) {
        const int16_t* d = disparity + static_cast<size_t>(y) * static_cast<size_t>(w);
        const uint32_t first = static_cast<uint32_t>(y) * static_cast<uint32_t>(w);
        uint32_t run = first;
        int open = -1; // the first pixel of a run that goes on into the next chunk
        for (int x0 = 0; x0 < w; x0 += kChunk) {
            const ChunkBits bits = chunkBits(d, w, x0, invalid, max_step);
            // A run starts at a valid pixel that does not go on from its left neighbour,
            // and ends at one whose right neighbour does not go on from it: starts and
            // ends alternate along the row.
            uint64_t starts = bits.valid & ~bits.goes_on;
            uint64_t ends = bits.valid & ~((bits.goes_on >> 1) | (bits.next_goes_on << 63));
            for (;;) {
                if (open < 0) {
                    if (starts == 0)
                        break;
                    open = x0 + std::countr_zero(starts);
                    starts &= starts - 1;
                }
                if (ends == 0)
                    break;
                const int end = x0 + std::countr_zero(ends) + 1;
                ends &= ends - 1;
                begin_[run] = static_cast<uint16_t>(open);
                end_[run] = static_cast<uint16_t>(end);
                parent_[run] = run;
                size_[run] = static_cast<uint32_t>(end - open);
                ++run;
                open = -1;
            }
        }
        runs_[static_cast<size_t>(y)] = run - first;
        if (y > y0)
            joinRows(disparity, max_step, y);
    }
}

void SpeckleFilter::joinRows(const int16_t* disparity, int max_step, int y)
{
    const size_t w = static_cast<size_t>(width_);
    const int16_t* d = disparity + static_cast<size_t>(y) * w;
    const int16_t* above = d - w;
    uint32_t a = static_cast<uint32_t>(y - 1) * static_cast<uint32_t>(w);
    const uint32_t a_end = a + runs_[static_cast<size_t>(y) - 1];
    uint32_t b = static_cast<uint32_t>(y) * static_cast<uint32_t>(w);
    const uint32_t b_end = b + runs_[static_cast<size_t>(y)];
    // Both rows' runs in order of position: each pair that overlaps is looked at once, and
    // the first pixel of the overlap that belongs with the one above joins the two (on a
    // surface, the first pixel does: a mask of the whole row would cost more).
    while (a < a_end && b < b_end) {
        const int from = std::max(begin_[a], begin_[b]);
        const int to = std::min(end_[a], end_[b]);
        for (int x = from; x < to; ++x) {
            if (together(d[x], above[x], max_step) != 0) {
                const uint32_t ra = rootHalving(a), rb = rootHalving(b);
                if (ra != rb)
                    join(ra, rb);
                break;
            }
        }
        if (end_[a] <= end_[b])
            ++a;
        else
            ++b;
    }
}

uint32_t SpeckleFilter::root(uint32_t region) const
{
    while (parent_[region] != region)
        region = parent_[region];
    return region;
}

void SpeckleFilter::joinBands(const int16_t* disparity, int max_step, const int* band_starts,
                              int bands)
{
    for (int band = 1; band < bands; ++band)
        if (band_starts[band] > 0 && band_starts[band] < height_)
            joinRows(disparity, max_step, band_starts[band]);
}

void SpeckleFilter::removeBand(int16_t* disparity, int16_t invalid, int max_size, int y0,
                               int y1) const
{
    const size_t w = static_cast<size_t>(width_);
    const auto small = static_cast<uint32_t>(std::max(0, max_size));
    for (int y = y0; y < y1; ++y) {
        int16_t* d = disparity + static_cast<size_t>(y) * w;
        const uint32_t first = static_cast<uint32_t>(y) * static_cast<uint32_t>(w);
        const uint32_t end = first + runs_[static_cast<size_t>(y)];
        for (uint32_t run = first; run < end; ++run)
            if (size_[root(run)] < small)
                std::fill(d + begin_[run], d + end_[run], invalid);
    }
}

} // namespace stereod::sgm
