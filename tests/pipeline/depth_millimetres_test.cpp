// depthToMillimetres, the depth snapshot of every published frame: the same millimetres
// as rounding the depth in double precision (what the depth PNG writer has always
// stored), at every millimetre boundary from 0 to 65.536 m, for the values that are not
// depths, and on rows of any length and layout.

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "pipeline/depth_io.hpp"

namespace stereod {
namespace {

// The definition: round(z * 1000) in double; stored when 1..65535, else 0 (invalid).
uint16_t referenceMillimetres(float z_m)
{
    if (!std::isfinite(z_m))
        return 0;
    const double mm = std::round(static_cast<double>(z_m) * 1000.0);
    return mm >= 1.0 && mm <= 65535.0 ? static_cast<uint16_t>(mm) : 0;
}

// Count of pixels that differ from the definition; the first one in `first_bad`.
int countMismatches(const cv::Mat& depth_m, const cv::Mat& depth_mm, float& first_bad)
{
    int mismatches = 0;
    for (int y = 0; y < depth_m.rows; ++y)
        for (int x = 0; x < depth_m.cols; ++x) {
            const float z = depth_m.at<float>(y, x);
            if (depth_mm.at<uint16_t>(y, x) != referenceMillimetres(z)) {
                if (mismatches == 0)
                    first_bad = z;
                ++mismatches;
            }
        }
    return mismatches;
}

TEST(DepthToMillimetres, RoundsLikeDoublePrecisionAtEveryMillimetreBoundary)
{
    // Around every half millimetre from 0 to 65536.5 mm: the float nearest to it and the
    // four floats on each side, where rounding up or down is decided.
    std::vector<float> values;
    constexpr float kInf = std::numeric_limits<float>::infinity();
    for (int k = 0; k <= 65537; ++k) {
        float z = static_cast<float>((k + 0.5) / 1000.0);
        for (int i = 0; i < 4; ++i)
            z = std::nextafter(z, 0.0f);
        for (int i = 0; i < 9; ++i) {
            values.push_back(z);
            z = std::nextafter(z, kInf);
        }
    }
    const std::vector<float> special = {0.0f,    -0.0f,    -0.001f,
                                        -70.0f,  1e-30f,   std::numeric_limits<float>::denorm_min(),
                                        65.535f, 65.5355f, 65.536f,
                                        70.0f,   1e30f,    std::numeric_limits<float>::max(),
                                        kInf,    -kInf,    std::numeric_limits<float>::quiet_NaN()};
    values.insert(values.end(), special.begin(), special.end());

    const cv::Mat depth_m(1, static_cast<int>(values.size()), CV_32FC1, values.data());
    cv::Mat depth_mm;
    depthToMillimetres(depth_m, depth_mm);
    ASSERT_EQ(depth_mm.type(), CV_16UC1);
    ASSERT_EQ(depth_mm.size(), depth_m.size());
    float first_bad = 0.0f;
    EXPECT_EQ(countMismatches(depth_m, depth_mm, first_bad), 0) << "first at " << first_bad << " m";
    // The edges of the range, spelt out.
    const auto mmOf = [](float z) {
        const cv::Mat one(1, 1, CV_32FC1, cv::Scalar(z));
        cv::Mat out;
        depthToMillimetres(one, out);
        return out.at<uint16_t>(0, 0);
    };
    EXPECT_EQ(mmOf(0.0004f), 0); // rounds to 0 mm: invalid
    EXPECT_EQ(mmOf(0.0006f), 1);
    EXPECT_EQ(mmOf(65.535f), 65535);
    EXPECT_EQ(mmOf(65.5356f), 0); // rounds to 65536 mm: does not fit, invalid
    EXPECT_EQ(mmOf(1e30f), 0);
}

TEST(DepthToMillimetres, RowsOfAnyLengthAndLayout)
{
    // Widths around the blocks the conversion works in, and a view into a bigger image
    // (rows not contiguous), with depths in and out of range.
    cv::RNG rng(7);
    for (int width : {1, 63, 64, 65, 130, 641}) {
        cv::Mat big(9, width + 5, CV_32FC1);
        rng.fill(big, cv::RNG::UNIFORM, -5.0, 80.0);
        big.at<float>(0, 0) = std::numeric_limits<float>::quiet_NaN();
        const cv::Mat view = big(cv::Rect(3, 1, width, 7));
        cv::Mat depth_mm;
        depthToMillimetres(view, depth_mm);
        float first_bad = 0.0f;
        EXPECT_EQ(countMismatches(view, depth_mm, first_bad), 0)
            << "width " << width << ", first at " << first_bad << " m";
        cv::Mat whole;
        depthToMillimetres(big, whole);
        EXPECT_EQ(countMismatches(big, whole, first_bad), 0) << "width " << width + 5;
    }
}

} // namespace
} // namespace stereod
