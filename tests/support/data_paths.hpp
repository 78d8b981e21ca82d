#pragma once
// Where the real data the tests run on are: the shared stereo data with ground truth
// (Middlebury, KITTI, ETH3D, a real rig) and opencv-doc's samples. Read in place, never
// copied.

#include <string>

namespace stereod::test {

std::string sharedDataDir();
std::string opencvSamplesDir();
// Middlebury 2001's tsukuba pair (im3, im4, disp3): the tests' everyday scene.
std::string tsukubaDir();
// The rig the tests give tsukuba (rectified, 384x288): its disparities (5..15 px) are then
// depths of 0.5 to 1.6 m, within the depth range the service sees with its defaults.
inline constexpr double kTsukubaFocalPx = 615.0;
inline constexpr double kTsukubaBaselineM = 0.013;

} // namespace stereod::test
