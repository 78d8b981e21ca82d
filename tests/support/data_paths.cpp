#include "tests/support/data_paths.hpp"

namespace stereod::test {

std::string sharedDataDir()
{
    return STEREOD_SHARED_DATA_DIR;
}

std::string opencvSamplesDir()
{
    return STEREOD_OPENCV_SAMPLES_DIR;
}

std::string tsukubaDir()
{
    return sharedDataDir() + "/middlebury/tsukuba";
}

} // namespace stereod::test
