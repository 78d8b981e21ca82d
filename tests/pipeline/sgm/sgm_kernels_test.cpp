// The SIMD kernels against the scalar reference, kernel by kernel and on every target
// Highway compiled that this processor runs: the contract in sgm_kernels.hpp says both
// compute exactly the same integers. Rows are deterministic
// pseudo-random texture; widths include tiny ones and ones that are no multiple of a
// vector, disparity counts 16..256, and the first disparity zero, positive and negative.
// Buffers are sized exactly as the contract asks (and no larger), so that the
// AddressSanitizer run also catches a kernel reading or writing outside them.

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ostream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/sgm/sgm_kernels.hpp"
#include "tests/pipeline/sgm/synthetic_pair.hpp"
#include "tests/pipeline/simd_target_name.hpp"

namespace stereod::sgm {

// gtest prints a test's parameter: the target's name, not the table's bytes.
void PrintTo(const SgmKernels& kernels, std::ostream* os)
{
    *os << kernels.target;
}

namespace {

using test::Random;

constexpr int kWidths[] = {1, 2, 5, 16, 31, 32, 33, 63, 100};
constexpr int kNumDisparities[] = {16, 64, 128, 256};
constexpr int kMinDisparities[] = {0, 7, -5};

// Census window sides (bits = w * h - 1: 2 to 62, i.e. 1 to 8 planes) with path penalties
// that keep the largest cost + P2 within 255, the settings' invariant; the last one sits
// right at it.
struct CostModel {
    int census_width, census_height;
    uint8_t p1, p2;
    int bits() const { return census_width * census_height - 1; }
    int planes() const { return (bits() + 7) / 8; }
};
constexpr CostModel kCostModels[] = {{7, 5, 9, 96}, {3, 1, 1, 40}, {9, 7, 7, 193}};

int lanesFor(int num_disparities)
{
    return (num_disparities + kLaneAlign - 1) / kLaneAlign * kLaneAlign;
}

std::string describe(int width, int num_disparities, int min_disparity)
{
    return "width " + std::to_string(width) + ", num_disparities " +
           std::to_string(num_disparities) + ", min_disparity " + std::to_string(min_disparity);
}

template <typename T> void fillRandom(std::vector<T>& v, Random& random, int lo, int hi)
{
    for (T& x : v)
        x = static_cast<T>(random.uniform(lo, hi));
}

// Census planes of one row pair: the right row is the left one shifted by a few pixels
// with some bits flipped, so that the costs have real minima, not only noise.
struct CensusRowPair {
    std::vector<std::vector<uint8_t>> left, right;
    // right_reversed: exactly the bytes the contract requires to be readable, from
    // min_disparity - 1 to width + min_disparity + lanes around its start; values outside
    // the row are garbage on purpose.
    std::vector<std::vector<uint8_t>> reversed_storage;
    std::vector<const uint8_t*> left_ptr, right_ptr, reversed_ptr;
    CensusRows rows;

    CensusRowPair(int width, int min_disparity, int lanes, int planes, Random& random)
    {
        const int shift = random.uniform(0, 12);
        const int lo = std::min(0, min_disparity - 1);
        const int hi = std::max(width, width + min_disparity + lanes);
        left.resize(static_cast<size_t>(planes));
        right.resize(static_cast<size_t>(planes));
        reversed_storage.resize(static_cast<size_t>(planes));
        for (int p = 0; p < planes; ++p) {
            auto& l = left[static_cast<size_t>(p)];
            auto& r = right[static_cast<size_t>(p)];
            auto& rr = reversed_storage[static_cast<size_t>(p)];
            l.resize(static_cast<size_t>(width));
            r.resize(static_cast<size_t>(width));
            fillRandom(l, random, 0, 255);
            for (int x = 0; x < width; ++x) {
                const int from = std::min(width - 1, x + shift);
                r[static_cast<size_t>(x)] = static_cast<uint8_t>(
                    l[static_cast<size_t>(from)] ^
                    (1u << random.uniform(0, 7)) * static_cast<unsigned>(random.uniform(0, 1)));
            }
            rr.resize(static_cast<size_t>(hi - lo));
            fillRandom(rr, random, 0, 255);
            for (int j = 0; j < width; ++j)
                rr[static_cast<size_t>(j - lo)] = r[static_cast<size_t>(width - 1 - j)];
            left_ptr.push_back(l.data());
            right_ptr.push_back(r.data());
            reversed_ptr.push_back(rr.data() - lo);
        }
        rows = CensusRows{left_ptr.data(), right_ptr.data(), reversed_ptr.data(), planes};
    }
};

// The five rows of a WinnerRows, `width` entries each and no more, set to `fill`.
struct WinnerStorage {
    static constexpr int kFields = 5;
    static constexpr const char* kNames[kFields] = {"best_lane", "best_sum", "second_sum",
                                                    "below_sum", "above_sum"};
    std::vector<std::vector<uint16_t>> fields;
    WinnerRows rows;

    WinnerStorage(int width, uint16_t fill)
        : fields(kFields, std::vector<uint16_t>(static_cast<size_t>(width), fill)),
          rows{fields[0].data(), fields[1].data(), fields[2].data(), fields[3].data(),
               fields[4].data()}
    {
    }
    const std::vector<uint16_t>& field(int i) const { return fields[static_cast<size_t>(i)]; }
};

// A cost row as the matcher makes it: the scalar reference's costs of a census row pair.
std::vector<uint8_t> costRow(int width, int min_disparity, int num_disparities,
                             const CostModel& model, Random& random)
{
    const int lanes = lanesFor(num_disparities);
    const CensusRowPair census(width, min_disparity, lanes, model.planes(), random);
    std::vector<uint8_t> cost(static_cast<size_t>(width) * static_cast<size_t>(lanes));
    scalarKernels().cost_row(census.rows, width, min_disparity, num_disparities, lanes,
                             static_cast<uint8_t>(model.bits()), cost.data(), nullptr);
    return cost;
}

// P2 per pixel, lowered at random as the gradient adaptation does, never below p1 + 1.
std::vector<uint8_t> penalties(int width, const CostModel& model, Random& random)
{
    std::vector<uint8_t> p2(static_cast<size_t>(width));
    fillRandom(p2, random, model.p1 + 1, model.p2);
    return p2;
}

// Lane spans of a guided search for one row (sgm_kernels.hpp): neighbours' spans overlap,
// touch, or lie apart, some cover every lane; or none (every lane) when `with_spans` is false.
std::vector<LaneSpan> laneSpans(bool with_spans, int width, int lanes, Random& random)
{
    if (!with_spans)
        return {};
    const int units = lanes / kLaneAlign;
    std::vector<LaneSpan> spans(static_cast<size_t>(width));
    for (LaneSpan& span : spans) {
        const int first = random.uniform(0, 3) == 0 ? 0 : random.uniform(0, units - 1);
        const int end = random.uniform(0, 3) == 0 ? units : random.uniform(first + 1, units);
        span = {static_cast<uint8_t>(first), static_cast<uint8_t>(end)};
    }
    return spans;
}

const LaneSpan* spansOrNull(const std::vector<LaneSpan>& spans)
{
    return spans.empty() ? nullptr : spans.data();
}

// Whether lane k of pixel x is searched.
bool searched(const std::vector<LaneSpan>& spans, int x, int k)
{
    if (spans.empty())
        return true;
    const LaneSpan span = spans[static_cast<size_t>(x)];
    return k >= kLaneAlign * span.first && k < kLaneAlign * span.end;
}

// Every kernel on every target Highway compiled that this processor runs, not only the
// one it picks (an AVX-512 machine tests AVX2 too).
class SgmKernelsOnEveryTarget : public ::testing::TestWithParam<SgmKernels> {};

INSTANTIATE_TEST_SUITE_P(Targets, SgmKernelsOnEveryTarget,
                         ::testing::ValuesIn(simdKernelsOfEveryTarget()),
                         simdTargetName<SgmKernels>);

TEST(SgmKernelsTest, SimdTargetIsNamed)
{
    const char* target = simdKernels().target;
    ASSERT_NE(target, nullptr);
    EXPECT_STRNE(target, "");
    EXPECT_STREQ(scalarKernels().target, "scalar");
    // scripts/cross-aarch64.sh reads this line.
    std::printf("simd target: %s\n", target);
}

TEST_P(SgmKernelsOnEveryTarget, CensusRowMatchesScalar)
{
    Random random(1);
    const int windows[][2] = {{7, 5}, {9, 7}, {3, 1}, {5, 5}, {3, 3}, {1, 3}};
    for (const auto& window : windows)
        for (int width : {1, 2, 5, 31, 32, 33, 63, 64, 65, 100}) {
            const int census_width = window[0], census_height = window[1];
            const int rx = census_width / 2, ry = census_height / 2;
            const int planes = (census_width * census_height - 1 + 7) / 8;
            SCOPED_TRACE("census " + std::to_string(census_width) + "x" +
                         std::to_string(census_height) + ", width " + std::to_string(width));
            // An image padded by the window's half sides, three rows of census.
            const int rows = 3;
            const size_t stride = static_cast<size_t>(width + 2 * rx);
            std::vector<uint8_t> image(stride * static_cast<size_t>(rows + 2 * ry));
            fillRandom(image, random, 0, 255);
            for (size_t i = 0; i < image.size(); i += 7)
                image[i] = 128; // some equal neighbours: not darker, bit clear
            for (int y = 0; y < rows; ++y) {
                const uint8_t* center =
                    image.data() + static_cast<size_t>(y + ry) * stride + static_cast<size_t>(rx);
                std::vector<std::vector<uint8_t>> expected(static_cast<size_t>(planes)),
                    actual(static_cast<size_t>(planes));
                std::vector<uint8_t*> expected_ptr, actual_ptr;
                for (int p = 0; p < planes; ++p) {
                    expected[static_cast<size_t>(p)].assign(static_cast<size_t>(width), 0xA5);
                    actual[static_cast<size_t>(p)].assign(static_cast<size_t>(width), 0x5A);
                    expected_ptr.push_back(expected[static_cast<size_t>(p)].data());
                    actual_ptr.push_back(actual[static_cast<size_t>(p)].data());
                }
                scalarKernels().census_row(center, stride, width, census_width, census_height,
                                           expected_ptr.data());
                GetParam().census_row(center, stride, width, census_width, census_height,
                                      actual_ptr.data());
                for (int p = 0; p < planes; ++p)
                    ASSERT_EQ(actual[static_cast<size_t>(p)], expected[static_cast<size_t>(p)])
                        << "plane " << p << ", row " << y;
            }
        }
}

// Without spans every lane; with spans the lanes of each pixel's span, the others left as
// they were.
TEST_P(SgmKernelsOnEveryTarget, CostRowMatchesScalar)
{
    Random random(2);
    for (const CostModel& model : kCostModels)
        for (bool with_spans : {false, true})
            for (int width : kWidths)
                for (int num_disparities : kNumDisparities)
                    for (int min_disparity : kMinDisparities) {
                        SCOPED_TRACE(describe(width, num_disparities, min_disparity) + ", planes " +
                                     std::to_string(model.planes()) +
                                     (with_spans ? ", spans" : ""));
                        const int lanes = lanesFor(num_disparities);
                        const CensusRowPair census(width, min_disparity, lanes, model.planes(),
                                                   random);
                        const auto spans = laneSpans(with_spans, width, lanes, random);
                        const size_t cells =
                            static_cast<size_t>(width) * static_cast<size_t>(lanes);
                        std::vector<uint8_t> expected(cells, 0xA5), actual(cells, 0xA5);
                        const auto invalid = static_cast<uint8_t>(model.bits());
                        scalarKernels().cost_row(census.rows, width, min_disparity, num_disparities,
                                                 lanes, invalid, expected.data(),
                                                 spansOrNull(spans));
                        GetParam().cost_row(census.rows, width, min_disparity, num_disparities,
                                            lanes, invalid, actual.data(), spansOrNull(spans));
                        ASSERT_EQ(actual, expected);
                    }
}

// A row of path blocks as the matcher allocates it: pads at 255 (the contract sets them
// once, when the buffer is made), L values garbage until a kernel writes them.
std::vector<uint8_t> pathBlocks(int width, int lanes, Random& random)
{
    const size_t block = pathBlockBytes(lanes);
    std::vector<uint8_t> blocks(static_cast<size_t>(width) * block, 255);
    for (int x = 0; x < width; ++x)
        for (int k = 0; k < lanes; ++k)
            blocks[static_cast<size_t>(x) * block + kPathPad + static_cast<size_t>(k)] =
                static_cast<uint8_t>(random.uniform(0, 255));
    return blocks;
}

// L values of every block of a row of path blocks, and the pads around them that the next
// step's L[k - 1] and L[k + 1] read: the contract keeps those at 255. Byte 0 of a block
// belongs to the kernels (the SIMD ones keep min L there) and is not compared.
// With spans, the L values of each pixel's span alone.
void expectBlocksMatch(const std::vector<uint8_t>& actual, const std::vector<uint8_t>& expected,
                       int width, int lanes, const std::vector<LaneSpan>& spans)
{
    const size_t block = pathBlockBytes(lanes);
    for (int x = 0; x < width; ++x) {
        const uint8_t* a = actual.data() + static_cast<size_t>(x) * block;
        const uint8_t* e = expected.data() + static_cast<size_t>(x) * block;
        for (int k = 0; k < lanes; ++k) {
            if (searched(spans, x, k)) {
                ASSERT_EQ(a[kPathPad + k], e[kPathPad + k])
                    << "path cost of pixel " << x << ", lane " << k;
            }
        }
        for (const uint8_t* b : {a, e}) {
            ASSERT_TRUE(std::all_of(b + 1, b + kPathPad, [](uint8_t v) { return v == 255; }))
                << "pad before pixel " << x << (b == a ? " (simd)" : " (scalar)");
            ASSERT_TRUE(
                std::all_of(b + kPathPad + lanes, b + block, [](uint8_t v) { return v == 255; }))
                << "pad after pixel " << x << (b == a ? " (simd)" : " (scalar)");
        }
    }
}

// The paths from above (none, the vertical one, or all three) and the left->right path,
// over a few rows: each implementation keeps its own previous row, as the matcher does.
TEST_P(SgmKernelsOnEveryTarget, PathsForwardMatchesScalar)
{
    Random random(3);
    constexpr int kRows = 4; // the paths' first row (no previous row), then three more
    static constexpr int kDx[3] = {0, -1, 1};
    for (const CostModel& model : kCostModels)
        for (int above : {0, 1, 2, 3})
            for (int width : kWidths)
                for (int num_disparities : kNumDisparities)
                    for (int min_disparity : kMinDisparities)
                        for (bool with_spans : {false, true}) {
                            SCOPED_TRACE(describe(width, num_disparities, min_disparity) +
                                         ", paths from above " + std::to_string(above) +
                                         (with_spans ? ", spans" : ""));
                            const int lanes = lanesFor(num_disparities);
                            std::vector<LaneSpan> prev_spans;
                            std::vector<uint8_t> expected_rows[3][2], actual_rows[3][2];
                            for (int i = 0; i < above; ++i)
                                for (int r = 0; r < 2; ++r) {
                                    expected_rows[i][r] = pathBlocks(width, lanes, random);
                                    actual_rows[i][r] = expected_rows[i][r];
                                }
                            std::vector<uint8_t> expected_along = pathBlocks(width, lanes, random);
                            std::vector<uint8_t> actual_along = expected_along;
                            for (int y = 0; y < kRows; ++y) {
                                SCOPED_TRACE("row " + std::to_string(y));
                                const auto cost =
                                    costRow(width, min_disparity, num_disparities, model, random);
                                std::vector<uint8_t> p2_above[3];
                                const uint8_t* p2_ptr[3];
                                const uint8_t* expected_prev[3];
                                const uint8_t* actual_prev[3];
                                uint8_t* expected_cur[3];
                                uint8_t* actual_cur[3];
                                const int cur = y & 1;
                                for (int i = 0; i < above; ++i) {
                                    p2_above[i] = penalties(width, model, random);
                                    p2_ptr[i] = p2_above[i].data();
                                    expected_prev[i] =
                                        y == 0 ? nullptr : expected_rows[i][cur ^ 1].data();
                                    actual_prev[i] =
                                        y == 0 ? nullptr : actual_rows[i][cur ^ 1].data();
                                    expected_cur[i] = expected_rows[i][cur].data();
                                    actual_cur[i] = actual_rows[i][cur].data();
                                }
                                const auto p2_along = penalties(width, model, random);
                                const auto spans = laneSpans(with_spans, width, lanes, random);
                                // The left->right path on odd rows only: the matcher's warm-up
                                // rows run the paths from above alone.
                                const bool along = above == 0 || y % 2 == 1;
                                scalarKernels().paths_forward(
                                    cost.data(), model.p1, width, lanes,
                                    AbovePaths{above, kDx, p2_ptr, expected_prev, expected_cur,
                                               spansOrNull(prev_spans)},
                                    p2_along.data(), along ? expected_along.data() : nullptr,
                                    spansOrNull(spans));
                                GetParam().paths_forward(
                                    cost.data(), model.p1, width, lanes,
                                    AbovePaths{above, kDx, p2_ptr, actual_prev, actual_cur,
                                               spansOrNull(prev_spans)},
                                    p2_along.data(), along ? actual_along.data() : nullptr,
                                    spansOrNull(spans));
                                for (int i = 0; i < above; ++i)
                                    ASSERT_NO_FATAL_FAILURE(expectBlocksMatch(actual_rows[i][cur],
                                                                              expected_rows[i][cur],
                                                                              width, lanes, spans))
                                        << "path from above " << i;
                                if (along) {
                                    ASSERT_NO_FATAL_FAILURE(expectBlocksMatch(
                                        actual_along, expected_along, width, lanes, spans))
                                        << "left->right path";
                                }
                                prev_spans = spans;
                            }
                        }
}

TEST_P(SgmKernelsOnEveryTarget, WinnersBackwardMatchesScalar)
{
    Random random(6);
    for (const CostModel& model : kCostModels)
        for (int others : {0, 1, 2, 3, 4})
            for (int width : kWidths)
                for (int num_disparities : kNumDisparities)
                    for (int min_disparity : kMinDisparities)
                        for (int levels : {3, 200})
                            for (bool with_spans : {false, true}) {
                                // 3 levels: many equal sums (ties go to the smallest lane);
                                // 200: few.
                                SCOPED_TRACE(describe(width, num_disparities, min_disparity) +
                                             ", other paths " + std::to_string(others) +
                                             ", levels " + std::to_string(levels) +
                                             (with_spans ? ", spans" : ""));
                                const int lanes = lanesFor(num_disparities);
                                const auto spans = laneSpans(with_spans, width, lanes, random);
                                const size_t block = pathBlockBytes(lanes);
                                const auto cost =
                                    costRow(width, min_disparity, num_disparities, model, random);
                                const auto p2 = penalties(width, model, random);
                                // The other paths' rows: a valley around a random best lane per
                                // pixel, noise on top, anywhere in 0..255 as 8-bit path costs are.
                                std::vector<std::vector<uint8_t>> rows(static_cast<size_t>(others));
                                std::vector<const uint8_t*> row_ptr;
                                for (auto& r : rows) {
                                    r = pathBlocks(width, lanes, random);
                                    for (int x = 0; x < width; ++x) {
                                        const int best = random.uniform(0, num_disparities - 1);
                                        for (int k = 0; k < lanes; ++k) {
                                            const int valley =
                                                std::abs(k - best) * 8 +
                                                random.uniform(0, levels - 1) * (200 / levels);
                                            r[static_cast<size_t>(x) * block + kPathPad +
                                              static_cast<size_t>(k)] =
                                                static_cast<uint8_t>(std::min(255, valley));
                                        }
                                    }
                                    row_ptr.push_back(r.data());
                                }
                                const PathRows path_rows{row_ptr.data(), others};
                                std::vector<uint8_t> path_scratch(2 * block, 255);
                                std::vector<uint16_t> sum_scratch(winnersSumScratch(lanes));
                                std::vector<uint16_t> scratch(
                                    winnersScratch(width, min_disparity, lanes));
                                WinnerStorage expected(width, 1);
                                WinnerStorage actual(width, 6);
                                std::vector<uint16_t> expected_right(static_cast<size_t>(width), 7);
                                std::vector<uint16_t> actual_right(static_cast<size_t>(width), 8);
                                fillRandom(sum_scratch, random, 0, 65535);
                                fillRandom(scratch, random, 0, 65535);
                                scalarKernels().winners_backward(
                                    cost.data(), p2.data(), model.p1, width, lanes, path_rows,
                                    min_disparity, num_disparities, path_scratch.data(),
                                    sum_scratch.data(), expected.rows, expected_right.data(),
                                    scratch.data(), spansOrNull(spans));
                                fillRandom(sum_scratch, random, 0, 65535);
                                fillRandom(scratch, random, 0, 65535);
                                std::fill(path_scratch.begin(), path_scratch.end(), uint8_t{255});
                                GetParam().winners_backward(
                                    cost.data(), p2.data(), model.p1, width, lanes, path_rows,
                                    min_disparity, num_disparities, path_scratch.data(),
                                    sum_scratch.data(), actual.rows, actual_right.data(),
                                    scratch.data(), spansOrNull(spans));
                                for (int field = 0; field < WinnerStorage::kFields; ++field)
                                    ASSERT_EQ(actual.field(field), expected.field(field))
                                        << WinnerStorage::kNames[field];
                                ASSERT_EQ(actual_right, expected_right);
                            }
}

// Winners as winners_backward() leaves them: the best sum the smallest, the second and the
// neighbours' sums at or above it, with ties, borderline uniqueness, best lanes at both
// ends of the range and past the lanes the left edge allows, and a right view that agrees
// exactly, nearly, not at all, or has no lane.
struct DecideCase {
    WinnerStorage winners;
    std::vector<uint16_t> right_lane;

    DecideCase(int width, int num_disparities, Random& random)
        : winners(width, 0), right_lane(rightLaneEntries(width))
    {
        for (int x = 0; x < width; ++x) {
            const auto at = static_cast<size_t>(x);
            const int end = random.uniform(0, 9);
            const int k = end == 0   ? 0
                          : end == 1 ? num_disparities - 1
                                     : random.uniform(0, num_disparities - 1);
            const int best =
                random.uniform(0, 3) == 0 ? random.uniform(0, 3) : random.uniform(0, 5 * 255 - 40);
            const int form = random.uniform(0, 9);
            const int second = form == 0   ? 0xFFFF
                               : form == 1 ? best
                               : form == 2 ? best + best * 9 / 100 + random.uniform(0, 1)
                                           : best + random.uniform(0, 40);
            const auto neighbour = [&](bool outside) {
                return outside ? 0 : best + random.uniform(0, 3) * random.uniform(0, 12);
            };
            winners.fields[0][at] = static_cast<uint16_t>(k);
            winners.fields[1][at] = static_cast<uint16_t>(best);
            winners.fields[2][at] = static_cast<uint16_t>(second);
            winners.fields[3][at] = static_cast<uint16_t>(neighbour(k == 0));
            winners.fields[4][at] = static_cast<uint16_t>(neighbour(k == num_disparities - 1));
        }
        for (uint16_t& lane : right_lane) {
            const int form = random.uniform(0, 5);
            lane = form == 0 ? uint16_t{0xFFFF}
                             : static_cast<uint16_t>(random.uniform(0, num_disparities - 1));
        }
    }
};

TEST_P(SgmKernelsOnEveryTarget, DecideRowMatchesScalar)
{
    Random random(8);
    int reported = 0, at_range_limit = 0, sub_pixel = 0, refused = 0;
    for (int width : kWidths)
        for (int num_disparities : kNumDisparities)
            for (int min_disparity : kMinDisparities)
                for (int lr_max_diff_px : {-1, 0, 2})
                    for (int uniqueness_percent : {0, 9}) {
                        SCOPED_TRACE(describe(width, num_disparities, min_disparity) + ", lr " +
                                     std::to_string(lr_max_diff_px) + ", uniqueness " +
                                     std::to_string(uniqueness_percent));
                        DecideCase c(width, num_disparities, random);
                        // Right lanes near the left view's, so that the check has work.
                        for (int x = 0; x < width; ++x) {
                            const int xr = x - min_disparity - c.winners.fields[0][x];
                            if (xr >= 0 && xr < width && random.uniform(0, 1) == 1)
                                c.right_lane[static_cast<size_t>(xr)] = static_cast<uint16_t>(
                                    std::max(0, c.winners.fields[0][x] + random.uniform(-3, 3)));
                        }
                        const DecideSettings settings{
                            min_disparity,  num_disparities,      uniqueness_percent,
                            lr_max_diff_px, random.uniform(0, 4), static_cast<float>(2 * 16 * 3)};
                        const size_t w = static_cast<size_t>(width);
                        std::vector<int16_t> expected_disparity(w, 1), actual_disparity(w, 2);
                        std::vector<uint8_t> expected_confidence(w, 3), actual_confidence(w, 4);
                        std::vector<uint8_t> expected_range(w, 5), actual_range(w, 6);
                        scalarKernels().decide_row(c.winners.rows, c.right_lane.data(), width,
                                                   settings, expected_disparity.data(),
                                                   expected_confidence.data(),
                                                   expected_range.data());
                        GetParam().decide_row(c.winners.rows, c.right_lane.data(), width, settings,
                                              actual_disparity.data(), actual_confidence.data(),
                                              actual_range.data());
                        ASSERT_EQ(actual_disparity, expected_disparity);
                        ASSERT_EQ(actual_confidence, expected_confidence);
                        ASSERT_EQ(actual_range, expected_range);
                        for (size_t x = 0; x < w; ++x) {
                            const int16_t d = expected_disparity[x];
                            reported += d != kNoDisparity ? 1 : 0;
                            refused += d == kNoDisparity ? 1 : 0;
                            sub_pixel += d != kNoDisparity && d % kSubpixel != 0 ? 1 : 0;
                            at_range_limit += expected_range[x];
                        }
                    }
    // Every way out of the kernel was taken, not only one.
    EXPECT_GT(reported, 1000);
    EXPECT_GT(refused, 1000);
    EXPECT_GT(sub_pixel, 100);
    EXPECT_GT(at_range_limit, 100);
}

// A tile's cost curve over a run of disparities: the same sums from both kernels, added to
// what the curve already held, for runs of every length around a vector's.
TEST_P(SgmKernelsOnEveryTarget, CostCurveMatchesScalar)
{
    Random random(23);
    for (const CostModel& model : kCostModels)
        for (int width : {33, 64, 100, 300})
            for (int count : {1, 15, 16, 31, 32, 33, 64, 100}) {
                if (count > width)
                    continue;
                SCOPED_TRACE("width " + std::to_string(width) + ", count " + std::to_string(count) +
                             ", planes " + std::to_string(model.planes()));
                const int lanes = lanesFor(width);
                const CensusRowPair census(width, 0, lanes, model.planes(), random);
                for (int trial = 0; trial < 8; ++trial) {
                    // Every right pixel inside the row: first <= x - (count - 1) ... x.
                    const int x = random.uniform(count - 1, width - 1);
                    const int first = random.uniform(std::max(0, x - width + 1), x - count + 1);
                    const size_t entries = static_cast<size_t>(lanesFor(count));
                    std::vector<uint16_t> expected(entries), actual(entries);
                    fillRandom(expected, random, 0, 1000);
                    std::copy(expected.begin(), expected.end(), actual.begin());
                    scalarKernels().cost_curve(census.rows, x, width, first, count,
                                               expected.data());
                    GetParam().cost_curve(census.rows, x, width, first, count, actual.data());
                    for (int k = 0; k < count; ++k)
                        ASSERT_EQ(actual[static_cast<size_t>(k)], expected[static_cast<size_t>(k)])
                            << "x " << x << ", first " << first << ", k " << k;
                }
            }
}

TEST_P(SgmKernelsOnEveryTarget, StepPenaltiesMatchScalar)
{
    Random random(9);
    // A table as the matcher makes it (P2 falling with the step to a floor), and one of
    // random values: every entry must be the one its step picks.
    uint8_t falling[kPenaltySteps], scattered[kPenaltySteps];
    for (int step = 0; step < kPenaltySteps; ++step) {
        falling[step] = static_cast<uint8_t>(std::max(17, 160 * 3 / (3 + step)));
        scattered[step] = static_cast<uint8_t>(random.uniform(0, 255));
    }
    for (const uint8_t* table : {falling, scattered})
        for (int width : {1, 15, 16, 17, 31, 32, 33, 64, 100, 640}) {
            SCOPED_TRACE("width " + std::to_string(width));
            std::vector<uint8_t> a(static_cast<size_t>(width)), b(a.size());
            for (size_t x = 0; x < a.size(); ++x) {
                a[x] = static_cast<uint8_t>(random.uniform(0, 255));
                // Small steps mostly, as between neighbouring pixels, and some large ones.
                const int step = random.uniform(0, 99) < 80 ? random.uniform(-40, 40)
                                                            : random.uniform(-255, 255);
                b[x] = static_cast<uint8_t>(std::clamp(a[x] + step, 0, 255));
            }
            std::vector<uint8_t> expected(a.size(), 7), actual(a.size(), 7);
            scalarKernels().step_penalties(a.data(), b.data(), width, table, expected.data());
            GetParam().step_penalties(a.data(), b.data(), width, table, actual.data());
            ASSERT_EQ(actual, expected);
            for (size_t x = 0; x < a.size(); ++x)
                ASSERT_EQ(expected[x], table[std::min(std::abs(a[x] - b[x]), kPenaltySteps - 1)]);
        }
}

TEST_P(SgmKernelsOnEveryTarget, MedianRowMatchesScalar)
{
    Random random(7);
    constexpr int16_t kNone = -32768;
    for (int width : {1, 2, 3, 4, 17, 31, 32, 33, 100})
        for (int invalid_percent : {0, 30, 90}) {
            SCOPED_TRACE("width " + std::to_string(width) + ", invalid " +
                         std::to_string(invalid_percent) + " %");
            std::vector<int16_t> rows(3 * static_cast<size_t>(width));
            for (int16_t& v : rows)
                v = random.uniform(0, 99) < invalid_percent
                        ? kNone
                        : static_cast<int16_t>(random.uniform(-200, 4000));
            std::vector<int16_t> expected(static_cast<size_t>(width), 11);
            std::vector<int16_t> actual(static_cast<size_t>(width), 11);
            const int16_t* up = rows.data();
            const int16_t* row = up + width;
            const int16_t* down = row + width;
            scalarKernels().median_row(up, row, down, width, kNone, expected.data());
            GetParam().median_row(up, row, down, width, kNone, actual.data());
            ASSERT_EQ(actual, expected);
        }
}

} // namespace
} // namespace stereod::sgm
