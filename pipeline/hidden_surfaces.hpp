#pragma once
// Surfaces the right camera cannot see, and the nearest they can be.
//
// In a rectified pair the scene just left of a near surface's left edge is hidden from
// the right camera behind that surface (an occlusion): no matcher measures it, and a
// reading from the measured pixels alone passes over whatever stands there between the
// near surface and the background (the real rig's Baumer scene 7: a chair hidden behind a
// block read as the wall 3.45 m away). What is hidden at column x cannot be nearer than
// the ray that grazes the near surface's edge: with the edge at x_e and its disparity d_e,
// its disparity is at most d_e - (x_e - x). The reading counts that bound for such a pixel
// (NearestObjectFinder::measure()): it can make a reading nearer than the truth, never
// farther.
//
// A run of pixels without a disparity is taken for a shadow when both its ends are
// surfaces (a few measured pixels that agree, not a stray match), the right end nearer
// than the left by more than kMinShadowStepPx, and the run as wide as that step (less a
// little, more the few pixels the left-right check and the speckle filter add): the width
// the geometry gives a shadow. A textureless run that fits
// by chance gets bounds too; they too can only make a reading nearer.
//
// Reentrant: a pure function over its arguments.

#include <opencv2/core/mat.hpp>

namespace stereod {

// A shadow's ends must differ by more than this (pixels): less is the same surface.
inline constexpr float kMinShadowStepPx = 2.0f;

// bound_px: CV_32FC1 of the disparity's size (reused when it already is); in rows
// [row_begin, row_end), the largest disparity a hidden pixel can have, +inf elsewhere
// (no bound: measured, or not a shadow). Rows outside the range are left untouched.
// disparity_px: CV_32FC1, +inf (or NaN) where no disparity was found.
void hiddenSurfaceBounds(const cv::Mat& disparity_px, int row_begin, int row_end,
                         cv::Mat& bound_px);

} // namespace stereod
