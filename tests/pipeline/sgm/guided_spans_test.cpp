// The guided search's spans (guided_spans.hpp) from coarse disparities made up for the
// purpose: each full-resolution pixel searches the blocks around what its coarse window
// measured, the whole range where the window measured too little or touched the coarse
// range's near end, an odd size's last row and column take the last coarse pixel's span,
// and a pool's bands predict exactly what one thread predicts.

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/sgm/band_pool.hpp"
#include "pipeline/sgm/guided_spans.hpp"

namespace stereod::sgm {
namespace {

constexpr float kNone = std::numeric_limits<float>::infinity();

struct Levels {
    CensusSgmSettings full, coarse;
};

// A full level of width x height searching 0..num_disparities-1 and its half-size level.
Levels levels(int width, int height, int num_disparities, int threads = 1)
{
    Levels l;
    l.full.width = width;
    l.full.height = height;
    l.full.num_disparities = num_disparities;
    l.full.threads = threads;
    l.coarse = l.full;
    l.coarse.width = width / 2;
    l.coarse.height = height / 2;
    return l;
}

struct Coarse {
    int width, height;
    std::vector<float> disparity;
    std::vector<uint8_t> limit;
    float& at(int x, int y) { return disparity[static_cast<size_t>(y * width + x)]; }
};

Coarse coarseOf(const Levels& l, float disparity)
{
    const size_t area = static_cast<size_t>(l.coarse.width * l.coarse.height);
    return {l.coarse.width, l.coarse.height, std::vector<float>(area, disparity),
            std::vector<uint8_t>(area, 0)};
}

LaneSpan spanAt(const GuidedSpans& guide, const Levels& l, int x, int y)
{
    return guide.spans()[static_cast<size_t>(y * l.full.width + x)];
}

TEST(GuidedSpansTest, APixelSearchesTheBlocksAroundItsWindowsDisparities)
{
    const Levels l = levels(64, 48, 128); // 4 blocks of 32 lanes
    Coarse coarse = coarseOf(l, 20.0f);   // 40 full-resolution pixels: block 1
    coarse.at(20, 10) = 30.0f;            // 60 +- 4: blocks 1 .. 2 in its window
    GuidedSpans guide(l.full, l.coarse);
    guide.predict(coarse.disparity.data(), coarse.limit.data());

    EXPECT_EQ(spanAt(guide, l, 4, 4).first, 1);
    EXPECT_EQ(spanAt(guide, l, 4, 4).end, 2);
    // Within kGuideRadius coarse pixels of (20, 10) the window holds both disparities.
    EXPECT_EQ(spanAt(guide, l, 2 * 22 + 1, 2 * 12 + 1).first, 1);
    EXPECT_EQ(spanAt(guide, l, 2 * 22 + 1, 2 * 12 + 1).end, 3);
    EXPECT_EQ(spanAt(guide, l, 2 * 23, 2 * 10).end, 2);
    EXPECT_TRUE(guide.narrow(0));
    EXPECT_LT(guide.searchedShare(), 0.3);
}

TEST(GuidedSpansTest, TooFewMeasuredOrANearEndSearchesTheWholeRange)
{
    const Levels l = levels(64, 48, 128);
    Coarse coarse = coarseOf(l, kNone);
    coarse.at(5, 5) = 20.0f; // three measured pixels in a window: too few
    coarse.at(6, 5) = 20.0f;
    coarse.at(5, 6) = 20.0f;
    coarse.at(20, 10) = 20.0f;
    coarse.at(21, 10) = 20.0f;
    coarse.at(20, 11) = 20.0f;
    coarse.at(21, 11) = 20.0f; // four: enough
    Coarse flagged = coarseOf(l, 20.0f);
    flagged.limit[static_cast<size_t>(10 * flagged.width + 20)] = 1;
    GuidedSpans guide(l.full, l.coarse), guide_flagged(l.full, l.coarse);
    guide.predict(coarse.disparity.data(), coarse.limit.data());
    guide_flagged.predict(flagged.disparity.data(), flagged.limit.data());

    EXPECT_FALSE(guide.narrow(static_cast<size_t>(2 * 5 * l.full.width + 2 * 5)));
    EXPECT_TRUE(guide.narrow(static_cast<size_t>(2 * 10 * l.full.width + 2 * 20)));
    // The flag reaches kGuideRadius coarse pixels around, no further.
    EXPECT_FALSE(guide_flagged.narrow(static_cast<size_t>(2 * 12 * l.full.width + 2 * 22)));
    EXPECT_TRUE(guide_flagged.narrow(static_cast<size_t>(2 * 13 * l.full.width + 2 * 20)));
    EXPECT_TRUE(guide_flagged.narrow(static_cast<size_t>(2 * 10 * l.full.width + 2 * 23)));
}

TEST(GuidedSpansTest, AnOddSizesLastRowAndColumnTakeTheLastCoarsePixels)
{
    const Levels l = levels(65, 49, 128);
    Coarse coarse = coarseOf(l, 20.0f); // 40 +- 4: block 1
    // 100 +- 4 (block 3) in the last columns and rows, as far as a window reaches.
    for (int y = 0; y < coarse.height; ++y)
        for (int x = 0; x < coarse.width; ++x)
            if (x >= coarse.width - 1 - kGuideRadius || y >= coarse.height - 1 - kGuideRadius)
                coarse.at(x, y) = 50.0f;
    GuidedSpans guide(l.full, l.coarse);
    guide.predict(coarse.disparity.data(), coarse.limit.data());

    const auto same = [](LaneSpan a, LaneSpan b) { return a.first == b.first && a.end == b.end; };
    for (int y = 0; y < l.full.height; ++y)
        EXPECT_TRUE(same(spanAt(guide, l, 64, y), spanAt(guide, l, 63, y))) << "row " << y;
    for (int x = 0; x < l.full.width; ++x)
        EXPECT_TRUE(same(spanAt(guide, l, x, 48), spanAt(guide, l, x, 47))) << "column " << x;
    EXPECT_EQ(spanAt(guide, l, 0, 0).first, 1);
    EXPECT_EQ(spanAt(guide, l, 64, 48).first, 3);
    EXPECT_EQ(spanAt(guide, l, 64, 48).end, 4);
}

TEST(GuidedSpansTest, APoolsBandsPredictWhatOneThreadPredicts)
{
    const Levels l = levels(131, 77, 256, 3);
    Coarse coarse = coarseOf(l, 0.0f);
    std::mt19937 random(25);
    std::uniform_real_distribution<float> disparity(-2.0f, 140.0f);
    std::uniform_int_distribution<int> pick(0, 99);
    // Patches of one disparity, holes and a few near-end flags.
    for (int y = 0; y < coarse.height; ++y)
        for (int x = 0; x < coarse.width; ++x) {
            const int p = pick(random);
            coarse.at(x, y) = p < 30 ? kNone : (x / 7 + y / 5) % 3 == 0 ? 20.5f : disparity(random);
            coarse.limit[static_cast<size_t>(y * coarse.width + x)] = p == 99 ? 1 : 0;
        }
    GuidedSpans alone(l.full, l.coarse), banded(l.full, l.coarse);
    BandPool pool(l.full.threads);
    alone.predict(coarse.disparity.data(), coarse.limit.data());
    banded.predict(coarse.disparity.data(), coarse.limit.data(), &pool);

    int narrow = 0;
    for (size_t i = 0; i < static_cast<size_t>(l.full.width * l.full.height); ++i) {
        ASSERT_EQ(alone.spans()[i].first, banded.spans()[i].first) << "pixel " << i;
        ASSERT_EQ(alone.spans()[i].end, banded.spans()[i].end) << "pixel " << i;
        narrow += alone.narrow(i) ? 1 : 0;
    }
    EXPECT_GT(narrow, 0);
    EXPECT_LT(narrow, l.full.width * l.full.height);
    EXPECT_EQ(alone.searchedShare(), banded.searchedShare());
}

} // namespace
} // namespace stereod::sgm
