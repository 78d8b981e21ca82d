#pragma once
// The demo's rig: opencv-doc's 13 chessboard pairs from a real 640x480 wide-angle stereo
// rig (left01..14.jpg, right01..14.jpg, no pair 10), and the calibration made from them
// as `stereoctl calibrate` makes it for scripts/demo.sh (9x6 inner corners, 25 mm squares).
// Header-only: the tests that include it link stereod_pipeline themselves.

#include <cstdio>
#include <string>
#include <vector>

#include "pipeline/calibration.hpp"
#include "pipeline/chessboard_calibration.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod::test {

struct DemoRigFiles {
    std::vector<std::string> left, right;
};

inline DemoRigFiles demoRigFiles()
{
    DemoRigFiles files;
    for (int i = 1; i <= 14; ++i) {
        if (i == 10)
            continue;
        char name[32];
        std::snprintf(name, sizeof name, "%02d.jpg", i);
        files.left.push_back(opencvSamplesDir() + "/left" + name);
        files.right.push_back(opencvSamplesDir() + "/right" + name);
    }
    return files;
}

// Calibrates from the 13 pairs (a second or two).
inline StereoCalibration demoRigCalibration()
{
    const DemoRigFiles files = demoRigFiles();
    ChessboardCalibrationOptions options;
    options.board = {9, 6, 0.025};
    return calibrateChessboard(files.left, files.right, options).calibration;
}

} // namespace stereod::test
