#pragma once
// The name of a kernel table's target as a parameterised test's name: the kernel tests run
// on every target Highway compiled (pipeline/simd_targets.hpp), one test per target.

#include <string>

#include <gtest/gtest.h>

namespace stereod {

template <class Table> std::string simdTargetName(const ::testing::TestParamInfo<Table>& info)
{
    return info.param.target;
}

} // namespace stereod
