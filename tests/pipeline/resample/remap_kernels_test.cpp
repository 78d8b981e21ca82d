// The remap kernel: the scalar reference against the four-term bilinear sum it stands for,
// and the SIMD kernel against the scalar one on every target Highway compiled that this
// processor runs. Sources are allocated exactly as large as their rows (no padding past
// the last pixel), so that the AddressSanitizer run also catches a kernel reading past
// the image's end; widths include ones that are no multiple of any vector.

#include <cstdint>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/resample/remap_kernels.hpp"
#include "tests/pipeline/simd_target_name.hpp"

namespace stereod::resample {

// gtest prints a test's parameter: the target's name, not the table's bytes.
void PrintTo(const RemapKernels& kernels, std::ostream* os)
{
    *os << kernels.target;
}

namespace {

constexpr int kTab = 1 << kInterBits;

// A source image of random bytes, exactly (rows - 1) * step + cols bytes long.
struct Source {
    std::vector<uint8_t> bytes;
    RemapSource view;

    Source(int cols, int rows, size_t step, std::mt19937& random)
        : bytes(static_cast<size_t>(rows - 1) * step + static_cast<size_t>(cols))
    {
        std::uniform_int_distribution<int> value(0, 255);
        for (uint8_t& b : bytes)
            b = static_cast<uint8_t>(value(random));
        view = {bytes.data(), step, cols, rows};
    }

    int at(int x, int y) const
    {
        if (x < 0 || x >= view.cols || y < 0 || y >= view.rows)
            return 0;
        return bytes[static_cast<size_t>(y) * view.step + static_cast<size_t>(x)];
    }
};

// One output row's map: source positions around the image, a share of them on its edge or
// wholly outside, and their offsets as neighbourhoodOffset() makes them.
struct RowMap {
    std::vector<int16_t> xy;
    std::vector<uint16_t> frac;
    std::vector<int32_t> offsets;
};

RowMap randomRow(const RemapSource& src, int width, std::mt19937& random)
{
    std::uniform_int_distribution<int> sx(-3, src.cols + 2);
    std::uniform_int_distribution<int> sy(-3, src.rows + 2);
    std::uniform_int_distribution<int> inside_x(0, src.cols - 1);
    std::uniform_int_distribution<int> inside_y(0, src.rows - 1);
    std::uniform_int_distribution<int> frac(0, kTab * kTab - 1);
    std::uniform_int_distribution<int> share(0, 99);
    RowMap row;
    for (int x = 0; x < width; ++x) {
        // Mostly inside, as a rectification map is: whole vectors then take the gathers.
        const bool anywhere = share(random) < 5;
        const int px = anywhere ? sx(random) : inside_x(random);
        const int py = anywhere ? sy(random) : inside_y(random);
        row.xy.push_back(static_cast<int16_t>(px));
        row.xy.push_back(static_cast<int16_t>(py));
        row.frac.push_back(static_cast<uint16_t>(frac(random)));
        row.offsets.push_back(neighbourhoodOffset(px, py, src));
    }
    return row;
}

// What the kernels stand for: cv::remap's four-term sum with weights in 1/1024.
std::vector<uint8_t> fourTermSum(const Source& source, const RowMap& row)
{
    std::vector<uint8_t> out;
    for (size_t i = 0; i < row.frac.size(); ++i) {
        const int x = row.xy[2 * i], y = row.xy[2 * i + 1];
        const int fx = row.frac[i] % kTab, fy = row.frac[i] / kTab;
        const int sum = source.at(x, y) * (kTab - fx) * (kTab - fy) +
                        source.at(x + 1, y) * fx * (kTab - fy) +
                        source.at(x, y + 1) * (kTab - fx) * fy + source.at(x + 1, y + 1) * fx * fy;
        out.push_back(
            static_cast<uint8_t>((sum + (1 << (2 * kInterBits - 1))) >> (2 * kInterBits)));
    }
    return out;
}

std::vector<uint8_t> remapped(const RemapKernels& kernels, const Source& source, const RowMap& row)
{
    // Exactly the row's bytes: a write past them is caught under AddressSanitizer.
    std::vector<uint8_t> out(row.frac.size());
    kernels.remap_row(source.view, row.offsets.data(), row.xy.data(), row.frac.data(),
                      static_cast<int>(row.frac.size()), out.data());
    return out;
}

TEST(RemapKernelsTest, NeighbourhoodsAreInsideOnTheEdgeOrOutside)
{
    const RemapSource src{nullptr, 12, 10, 6};
    EXPECT_EQ(neighbourhoodOffset(0, 0, src), 0);
    EXPECT_EQ(neighbourhoodOffset(3, 2, src), 2 * 12 + 3);
    EXPECT_EQ(neighbourhoodOffset(-1, 2, src), kOnTheEdge);
    EXPECT_EQ(neighbourhoodOffset(9, 2, src), kOnTheEdge); // its right neighbour is outside
    EXPECT_EQ(neighbourhoodOffset(3, 5, src), kOnTheEdge); // its lower neighbours are outside
    EXPECT_EQ(neighbourhoodOffset(-2, 2, src), kOutside);
    EXPECT_EQ(neighbourhoodOffset(10, 2, src), kOutside);
    EXPECT_EQ(neighbourhoodOffset(3, -2, src), kOutside);
    EXPECT_EQ(neighbourhoodOffset(8, 4, src), 4 * 12 + 8); // the last one wholly inside
}

TEST(RemapKernelsTest, ScalarIsTheFourTermBilinearSum)
{
    std::mt19937 random(7);
    for (const size_t step : {size_t{33}, size_t{40}}) {
        const Source source(33, 17, step, random);
        for (int width : {1, 7, 64, 333}) {
            const RowMap row = randomRow(source.view, width, random);
            EXPECT_EQ(remapped(scalarRemapKernels(), source, row), fourTermSum(source, row))
                << "width " << width << ", step " << step;
        }
    }
}

// The SIMD kernel on every target Highway compiled that this processor runs, not only
// the one it picks (an AVX-512 machine tests AVX2 too).
class RemapKernelsOnEveryTarget : public ::testing::TestWithParam<RemapKernels> {};

INSTANTIATE_TEST_SUITE_P(Targets, RemapKernelsOnEveryTarget,
                         ::testing::ValuesIn(simdRemapKernelsOfEveryTarget()),
                         simdTargetName<RemapKernels>);

TEST_P(RemapKernelsOnEveryTarget, RemapRowMatchesScalar)
{
    std::mt19937 random(11);
    for (const size_t step : {size_t{64}, size_t{71}}) {
        const Source source(64, 48, step, random);
        for (int width : {1, 3, 8, 15, 16, 17, 31, 33, 64, 100, 640}) {
            for (int trial = 0; trial < 20; ++trial) {
                const RowMap row = randomRow(source.view, width, random);
                ASSERT_EQ(remapped(GetParam(), source, row),
                          remapped(scalarRemapKernels(), source, row))
                    << "width " << width << ", step " << step << ", trial " << trial;
            }
        }
    }
}

// Rows as a rectification map makes them: the source position moves about a pixel per
// output pixel (here from half a pixel to two), the row drifts, and some steps go back.
// The SIMD kernel picks the pairs of a run of such pixels out of one loaded window of each
// row; runs that spread too wide, cross a row or reach the image's end are gathered pixel
// by pixel. Both ways, the reference's bytes.
TEST_P(RemapKernelsOnEveryTarget, SmoothMapsMatchScalar)
{
    std::mt19937 random(17);
    std::uniform_int_distribution<int> jitter(0, 9);
    std::uniform_int_distribution<int> frac(0, kTab * kTab - 1);
    const Source source(300, 40, 300, random);
    for (const double scale : {0.5, 0.9, 1.0, 1.1, 1.6, 2.0}) {
        for (const double drift : {0.0, 0.01, -0.03}) {
            for (const int start_y : {0, 17, 38}) {
                RowMap row;
                const int width = 290;
                for (int x = 0; x < width; ++x) {
                    const int back = jitter(random) == 0 ? -2 : 0; // now and then a step back
                    const int px = static_cast<int>(-3.0 + scale * x) + back;
                    const int py = start_y + static_cast<int>(drift * x);
                    row.xy.push_back(static_cast<int16_t>(px));
                    row.xy.push_back(static_cast<int16_t>(py));
                    row.frac.push_back(static_cast<uint16_t>(frac(random)));
                    row.offsets.push_back(neighbourhoodOffset(px, py, source.view));
                }
                ASSERT_EQ(remapped(GetParam(), source, row), fourTermSum(source, row))
                    << "scale " << scale << ", drift " << drift << ", row " << start_y;
            }
        }
    }
}

// Every neighbourhood of the image's last rows, down to the last pixel, stays inside it.
TEST_P(RemapKernelsOnEveryTarget, TheImagesLastPixelsStayInside)
{
    std::mt19937 random(13);
    const Source source(40, 8, 40, random);
    RowMap row;
    for (int y = 5; y < 8; ++y) {
        for (int x = 0; x < 40; ++x) {
            row.xy.push_back(static_cast<int16_t>(x));
            row.xy.push_back(static_cast<int16_t>(y));
            row.frac.push_back(static_cast<uint16_t>((x * 37 + y) % (kTab * kTab)));
            row.offsets.push_back(neighbourhoodOffset(x, y, source.view));
        }
    }
    EXPECT_EQ(remapped(GetParam(), source, row), fourTermSum(source, row));
}

TEST(RemapKernelsTest, SimdTargetIsNamed)
{
    const char* target = simdRemapKernels().target;
    ASSERT_NE(target, nullptr);
    EXPECT_STRNE(target, "");
    EXPECT_STREQ(scalarRemapKernels().target, "scalar");
}

} // namespace
} // namespace stereod::resample
