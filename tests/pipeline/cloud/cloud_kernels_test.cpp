// The cloud kernel: the scalar reference against the points it stands for, and the SIMD
// kernel against the scalar one, bit for bit, on every target Highway compiled that this
// processor runs. The output holds exactly the row's points (no room past them), so that
// the AddressSanitizer run also catches a kernel writing past a row's points, where the
// next row's belong to another thread.

#include <cmath>
#include <cstring>
#include <limits>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/cloud/cloud_kernels.hpp"
#include "tests/pipeline/simd_target_name.hpp"

namespace stereod::cloud {

// gtest prints a test's parameter: the target's name, not the table's bytes.
void PrintTo(const CloudKernels& kernels, std::ostream* os)
{
    *os << kernels.target;
}

namespace {

struct Row {
    std::vector<float> z, x_factor;
    std::vector<uint8_t> grey;
    size_t points = 0;
};

// A row of `width` depths, `valid_share` of them > 0 and the rest 0, negative, NaN or
// infinite-negative (none of which is a point), in runs as a depth map has them.
Row randomRow(int width, double valid_share, std::mt19937& random)
{
    std::uniform_real_distribution<float> depth(0.2f, 30.0f);
    std::uniform_real_distribution<double> share(0.0, 1.0);
    std::uniform_int_distribution<int> grey(0, 255), invalid(0, 3);
    Row row;
    bool valid = share(random) < valid_share;
    for (int u = 0; u < width; ++u) {
        if (share(random) < 0.2) // a run ends
            valid = share(random) < valid_share;
        const float not_a_point[] = {0.0f, -1.5f, std::numeric_limits<float>::quiet_NaN(),
                                     -std::numeric_limits<float>::infinity()};
        row.z.push_back(valid ? depth(random) : not_a_point[invalid(random)]);
        row.points += valid ? 1 : 0;
        row.grey.push_back(static_cast<uint8_t>(grey(random)));
        row.x_factor.push_back((static_cast<float>(u) - 0.37f * static_cast<float>(width)) /
                               613.5f);
    }
    return row;
}

std::vector<CloudPoint> pointsOf(const CloudKernels& kernels, const Row& row, float row_factor)
{
    std::vector<CloudPoint> out(row.points);
    const size_t written =
        kernels.points_row(row.z.data(), row.grey.data(), row.x_factor.data(), row_factor,
                           static_cast<int>(row.z.size()), row.points, out.data());
    EXPECT_EQ(written, row.points);
    return out;
}

bool sameBits(const std::vector<CloudPoint>& a, const std::vector<CloudPoint>& b)
{
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(CloudPoint)) == 0);
}

TEST(CloudKernelsTest, ScalarMakesAPointOfEachValidDepthInOrder)
{
    std::mt19937 random(3);
    const Row row = randomRow(100, 0.6, random);
    const std::vector<CloudPoint> points = pointsOf(scalarCloudKernels(), row, -0.25f);
    size_t i = 0;
    for (size_t u = 0; u < row.z.size(); ++u) {
        if (!(row.z[u] > 0.0f))
            continue;
        ASSERT_LT(i, points.size());
        EXPECT_EQ(points[i].x, row.x_factor[u] * row.z[u]);
        EXPECT_EQ(points[i].y, -0.25f * row.z[u]);
        EXPECT_EQ(points[i].z, row.z[u]);
        EXPECT_EQ(points[i].intensity, static_cast<float>(row.grey[u]));
        ++i;
    }
    EXPECT_EQ(i, points.size());
}

// The SIMD kernel on every target Highway compiled that this processor runs, not only
// the one it picks.
class CloudKernelsOnEveryTarget : public ::testing::TestWithParam<CloudKernels> {};

INSTANTIATE_TEST_SUITE_P(Targets, CloudKernelsOnEveryTarget,
                         ::testing::ValuesIn(simdCloudKernelsOfEveryTarget()),
                         simdTargetName<CloudKernels>);

TEST_P(CloudKernelsOnEveryTarget, PointsRowMatchesScalar)
{
    std::mt19937 random(5);
    for (const double valid_share : {0.0, 0.05, 0.5, 0.95, 1.0}) {
        for (const int width : {1, 3, 4, 7, 8, 15, 16, 17, 31, 33, 64, 100, 640}) {
            for (int trial = 0; trial < 10; ++trial) {
                const Row row = randomRow(width, valid_share, random);
                ASSERT_TRUE(sameBits(pointsOf(GetParam(), row, 0.125f),
                                     pointsOf(scalarCloudKernels(), row, 0.125f)))
                    << "width " << width << ", valid share " << valid_share << ", trial " << trial;
            }
        }
    }
}

TEST(CloudKernelsTest, SimdTargetIsNamed)
{
    const char* target = simdCloudKernels().target;
    ASSERT_NE(target, nullptr);
    EXPECT_STRNE(target, "");
    EXPECT_STREQ(scalarCloudKernels().target, "scalar");
}

} // namespace
} // namespace stereod::cloud
