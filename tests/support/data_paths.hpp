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

} // namespace stereod::test
