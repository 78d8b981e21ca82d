#pragma once
// The point cloud's inner loop: one row of a depth map made into the cloud's points, one
// per valid depth. Two implementations with one contract: a plain scalar reference and a
// SIMD one (Highway, dispatched at run time to the best target the processor has), which
// compacts a vector of pixels into its valid points at once instead of testing pixel by
// pixel. Both write the same points, bit for bit; tests hold them to it on every target.
//
// The standard library and Highway only. Reentrant: kernels keep no state.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "model/cloud_point.hpp"

namespace stereod::cloud {

struct CloudKernels {
    const char* target; // "scalar", "AVX2", "AVX3", "NEON", ...

    // For each pixel u in 0..width-1 whose depth z[u] is > 0, in order, the point
    // {x_factor[u] * z, row_factor * z, z, grey[u]} (x_factor[u] = (u - cx) / f as the
    // caller computes it, row_factor = (v - cy) / f). Writes exactly the row's points,
    // `points` of them (the caller counted them), to out; returns how many it wrote.
    size_t (*points_row)(const float* z, const uint8_t* grey, const float* x_factor,
                         float row_factor, int width, size_t points, CloudPoint* out);
};

const CloudKernels& scalarCloudKernels();
// The SIMD implementation for the best target this processor supports.
const CloudKernels& simdCloudKernels();
// The SIMD implementation for every target Highway compiled that this processor runs,
// best last (simd_targets.hpp): what the kernel tests hold against the scalar reference.
std::vector<CloudKernels> simdCloudKernelsOfEveryTarget();

} // namespace stereod::cloud
