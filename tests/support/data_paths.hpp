#pragma once
// Where the real data the tests run on are: the shared stereo data with ground truth
// (Middlebury, KITTI, ETH3D, a real rig) and opencv-doc's samples. Read in place, never
// copied.

#include <string>
#include <vector>

namespace stereod::test {

std::string sharedDataDir();
std::string opencvSamplesDir();
// opencv-doc's real rig: image `index` (1..14; there is no 10) of side "left" or "right",
// 640x480 views of a 9x6 (inner corners) chessboard.
std::string chessboardSample(const char* side, int index);
// Its first `count` pairs, in order (13: all of them).
void chessboardSamples(std::vector<std::string>& left, std::vector<std::string>& right,
                       int count = 13);

// Middlebury 2001's tsukuba pair (im3, im4, disp3): the tests' everyday scene.
std::string tsukubaDir();
// The rig the tests give tsukuba (rectified, 384x288): its disparities (5..15 px) are then
// depths of 0.5 to 1.6 m, within the depth range the service sees with its defaults.
inline constexpr double kTsukubaFocalPx = 615.0;
inline constexpr double kTsukubaBaselineM = 0.013;

} // namespace stereod::test
