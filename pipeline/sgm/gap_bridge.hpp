#pragma once
// Bridges short gaps in a disparity image: along each row, then each column, a run of at
// most `max_gap` pixels without disparity between two disparities within 1 px of each
// other gets the straight line between them. On man-made scenes (the `planar` tuning) the
// gaps are the insides of uniform patches and the edges between them, where matching
// declines a repeating pattern's ambiguous pixels; two ends that agree say the surface
// runs on between them. Ends that differ (a depth edge, an occlusion) leave the gap as
// it is.
//
// A pixel flagged at the near end of the range (range_limit) is a barrier: a surface may
// be nearer there than the range can see, and a line from the surfaces around it would
// put it farther than it is. A bridged pixel was inferred, not matched: it gets
// confidence kInferredConfidence, the lowest, so that `nearest.min_confidence` 2 leaves
// it out.

#include <cstdint>

namespace stereod::sgm {

inline constexpr uint8_t kInferredConfidence = 1;

// disparity: width * height values, row-major, fixed point (kSubpixel per pixel),
// kNoDisparity where none; confidence and range_limit (1: flagged): the same layout.
// only (the same layout, or nullptr: everywhere): a gap is bridged only where every pixel
// of it and both its ends are non-zero in `only`.
void bridgeGaps(int16_t* disparity, uint8_t* confidence, const uint8_t* range_limit, int width,
                int height, int max_gap, const uint8_t* only = nullptr);

} // namespace stereod::sgm
