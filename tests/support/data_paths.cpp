#include "tests/support/data_paths.hpp"

#include <cstdio>

namespace stereod::test {

std::string sharedDataDir()
{
    return STEREOD_SHARED_DATA_DIR;
}

std::string opencvSamplesDir()
{
    return STEREOD_OPENCV_SAMPLES_DIR;
}

std::string chessboardSample(const char* side, int index)
{
    char name[32];
    std::snprintf(name, sizeof name, "/%s%02d.jpg", side, index);
    return opencvSamplesDir() + name;
}

void chessboardSamples(std::vector<std::string>& left, std::vector<std::string>& right, int count)
{
    for (int i = 1; i <= 14 && static_cast<int>(left.size()) < count; ++i) {
        if (i == 10)
            continue;
        left.push_back(chessboardSample("left", i));
        right.push_back(chessboardSample("right", i));
    }
}

std::string tsukubaDir()
{
    return sharedDataDir() + "/middlebury/tsukuba";
}

} // namespace stereod::test
