#include <bit>
#include <cstring>

#include "pipeline/resample/remap_kernels.hpp"

namespace stereod::resample {
namespace {

constexpr int kInterTabSize = 1 << kInterBits;
constexpr int kWeightBits = 2 * kInterBits;
constexpr int kRounding = 1 << (kWeightBits - 1);

// A neighbour outside the source counts as 0 (BORDER_CONSTANT).
unsigned pixelOrZero(const RemapSource& src, int x, int y)
{
    const bool inside = x >= 0 && x < src.cols && y >= 0 && y < src.rows;
    return inside ? src.data[static_cast<size_t>(y) * src.step + static_cast<size_t>(x)] : 0u;
}

uint16_t pack(unsigned left, unsigned right)
{
    return static_cast<uint16_t>(left | (right << 8));
}

// Output pixels gathered per pass.
constexpr int kChunk = 64;

void remapRow(const RemapSource& src, const int32_t* offsets, const int16_t* xy,
              const uint16_t* frac, int width, uint8_t* out)
{
    uint16_t top[kChunk];
    uint16_t bottom[kChunk];
    for (int x0 = 0; x0 < width; x0 += kChunk) {
        const int n = width - x0 < kChunk ? width - x0 : kChunk;
        gatherNeighbours(src, offsets + x0, xy + 2 * x0, n, top, bottom);
        for (int i = 0; i < n; ++i)
            out[x0 + i] = blendNeighbours(top[i], bottom[i], frac[x0 + i]);
    }
}

} // namespace

void gatherNeighbours(const RemapSource& src, const int32_t* offsets, const int16_t* xy, int n,
                      uint16_t* top, uint16_t* bottom)
{
    for (int i = 0; i < n; ++i) {
        const int32_t offset = offsets[i];
        if (offset >= 0) {
            // One 16-bit load per pair: the left neighbour lands in the low byte, as pack()
            // puts it, on a little-endian machine.
            static_assert(std::endian::native == std::endian::little);
            std::memcpy(&top[i], src.data + offset, sizeof(uint16_t));
            std::memcpy(&bottom[i], src.data + offset + src.step, sizeof(uint16_t));
        } else if (offset == kOutside) {
            top[i] = 0;
            bottom[i] = 0;
        } else {
            const int sx = xy[2 * i], sy = xy[2 * i + 1];
            top[i] = pack(pixelOrZero(src, sx, sy), pixelOrZero(src, sx + 1, sy));
            bottom[i] = pack(pixelOrZero(src, sx, sy + 1), pixelOrZero(src, sx + 1, sy + 1));
        }
    }
}

uint8_t blendNeighbours(uint16_t top, uint16_t bottom, uint16_t frac)
{
    const int fx = frac & (kInterTabSize - 1);
    const int fy = (frac >> kInterBits) & (kInterTabSize - 1);
    const int tl = top & 0xff, tr = top >> 8;
    const int bl = bottom & 0xff, br = bottom >> 8;
    const int t = (tl << kInterBits) + (tr - tl) * fx;
    const int b = (bl << kInterBits) + (br - bl) * fx;
    return static_cast<uint8_t>((t * (kInterTabSize - fy) + b * fy + kRounding) >> kWeightBits);
}

const RemapKernels& scalarRemapKernels()
{
    static const RemapKernels kernels{"scalar", remapRow};
    return kernels;
}

} // namespace stereod::resample
