#pragma once
// The rectification's inner loop: one output row of the bilinear remap of an 8-bit grey
// image, each output pixel's 2x2 source neighbourhood found beforehand. Two
// implementations with one contract: a plain scalar reference and a SIMD one (Highway,
// dispatched at run time to the best target the processor has). Both write the same
// bytes; tests hold them to it on every target.
//
// The arithmetic is cv::remap's fixed point (pipeline/rectifier.cpp says why it is the
// same result): with fx, fy the sub-pixel position in 1/32 pixel,
//   top = tl * 32 + (tr - tl) * fx,   bottom = bl * 32 + (br - bl) * fx,
//   out = (top * (32 - fy) + bottom * fy + 512) >> 10.
//
// The standard library and Highway only. Reentrant: kernels keep no state.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace stereod::resample {

// Sub-pixel steps per pixel: 1 << kInterBits (cv::INTER_BITS), in x and in y.
inline constexpr int kInterBits = 5;

// Where a neighbourhood lies, in place of an offset: it straddles the source's edge (its
// neighbours outside count as 0), or no neighbour is inside (the output pixel is 0).
inline constexpr int32_t kOnTheEdge = -1;
inline constexpr int32_t kOutside = -2;

// The source image: rows of `cols` bytes, `step` bytes apart.
struct RemapSource {
    const uint8_t* data = nullptr;
    size_t step = 0;
    int cols = 0;
    int rows = 0;
};

// The offset of the neighbourhood whose top left neighbour is (sx, sy): sy * step + sx
// where all four neighbours lie inside the source, else kOnTheEdge or kOutside. The
// caller keeps rows * step below 2^31.
inline int32_t neighbourhoodOffset(int sx, int sy, const RemapSource& src)
{
    if (sx < -1 || sx >= src.cols || sy < -1 || sy >= src.rows)
        return kOutside;
    if (sx < 0 || sy < 0 || sx >= src.cols - 1 || sy >= src.rows - 1)
        return kOnTheEdge;
    return static_cast<int32_t>(static_cast<size_t>(sy) * src.step + static_cast<size_t>(sx));
}

// The two rows of n neighbourhoods as pairs, the left neighbour in the low byte:
// top[i] = tl | tr << 8, bottom[i] = bl | br << 8 (arguments as remap_row's below). Both
// implementations gather so: a 32-bit gather instruction, where the processor has one,
// was measured no faster (bench/README.md).
void gatherNeighbours(const RemapSource& src, const int32_t* offsets, const int16_t* xy, int n,
                      uint16_t* top, uint16_t* bottom);
// One output pixel from its neighbours' pairs and frac = fy * 32 + fx.
uint8_t blendNeighbours(uint16_t top, uint16_t bottom, uint16_t frac);

struct RemapKernels {
    const char* target; // "scalar", "AVX2", "AVX3", "NEON", ...

    // out[x] for x in 0..width-1, from offsets[x] (neighbourhoodOffset() of the pixel's
    // source position, or of a source whose step and size match `src`), frac[x] = fy * 32 +
    // fx, and for kOnTheEdge pixels xy[2x], xy[2x + 1], the top left neighbour's position.
    void (*remap_row)(const RemapSource& src, const int32_t* offsets, const int16_t* xy,
                      const uint16_t* frac, int width, uint8_t* out);
};

const RemapKernels& scalarRemapKernels();
// The SIMD implementation for the best target this processor supports.
const RemapKernels& simdRemapKernels();
// The SIMD implementation for every target Highway compiled that this processor runs,
// best last: what the kernel tests hold against the scalar reference. Not thread-safe: it
// switches Highway's chosen target while it collects them (and sets it back).
std::vector<RemapKernels> simdRemapKernelsOfEveryTarget();

} // namespace stereod::resample
