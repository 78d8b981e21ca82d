// census-sgm with its coarse level and near-field probe (pyramid_sgm.hpp) on synthetic pairs
// with known disparities: the extended range measures what lies beyond the full range, a
// surface beyond the extended range is near evidence and never a number, the full level
// alone is CensusSgm exactly, SIMD gives the scalar reference's output, and the probe marks
// only surfaces beyond the range.

#include <cmath>
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/sgm/census_sgm.hpp"
#include "pipeline/sgm/near_field_probe.hpp"
#include "pipeline/sgm/pyramid_sgm.hpp"
#include "tests/pipeline/sgm/synthetic_pair.hpp"

namespace stereod::sgm {
namespace {

using test::Layer;
using test::makeSyntheticPair;
using test::SyntheticPair;

constexpr int kWidth = 400, kHeight = 160;
// The full level searches 0..63; the coarse level 0..63 at half size, so 0..126.
constexpr int kNumDisparities = 64;
constexpr PixelRect kWholeImage{0, 0, kWidth, kHeight};

struct Output {
    std::vector<float> disparity_px;
    std::vector<uint8_t> confidence;
    std::vector<uint8_t> near_field;
    std::vector<float> coarse_only_px;
};

PyramidSgmSettings settingsFor(bool extended, bool simd = true, bool guided = false)
{
    PyramidSgmSettings s;
    s.guided_search = guided;
    // kNumDisparities is two vectors of lanes, so a span searches half of them at least:
    // the spans are taken whatever they search, so that the tests see them.
    s.guided_max_share = 1.0;
    s.full.width = kWidth;
    s.full.height = kHeight;
    s.full.num_disparities = kNumDisparities;
    s.full.use_simd = simd;
    s.extended_range = extended;
    return s;
}

// What `matcher` gives for the pair (every entry written over values it never writes).
Output computeWith(PyramidSgm& matcher, const SyntheticPair& pair, PixelRect probe = kWholeImage)
{
    const size_t area = pair.left.size();
    Output out{std::vector<float>(area, -1.0f), std::vector<uint8_t>(area, 77),
               std::vector<uint8_t>(area, 77), std::vector<float>(area, -1.0f)};
    const auto stride = static_cast<size_t>(pair.width);
    matcher.compute(pair.left.data(), stride, pair.right.data(), stride, probe,
                    {out.disparity_px.data(), out.confidence.data(), out.near_field.data(),
                     matcher.settings().extended_range ? out.coarse_only_px.data() : nullptr});
    return out;
}

Output match(const SyntheticPair& pair, const PyramidSgmSettings& settings,
             PixelRect probe = kWholeImage)
{
    PyramidSgm matcher(settings);
    return computeWith(matcher, pair, probe);
}

// A background at 8 px and one rectangle in front of it at `disparity`.
SyntheticPair sceneWith(int disparity)
{
    return makeSyntheticPair(kWidth, kHeight,
                             {{0, 0, kWidth, kHeight, 8}, {230, 40, 330, 120, disparity}}, 5);
}

// The pixels deep inside the rectangle (6 px off its edges), where the right view sees it.
template <typename Check> void forEachInside(const SyntheticPair& pair, Check check)
{
    for (int y = 46; y < 114; ++y)
        for (int x = 236; x < 324; ++x)
            if (!pair.occluded[pair.at(x, y)])
                check(pair.at(x, y));
}

TEST(PyramidSgmTest, TheExtendedRangeMeasuresASurfaceBeyondTheFullRange)
{
    const SyntheticPair pair = sceneWith(100); // beyond 63, within 126
    const Output out = match(pair, settingsFor(true));
    int inside = 0, measured = 0, evidence = 0;
    forEachInside(pair, [&](size_t i) {
        ++inside;
        const float d = out.disparity_px[i];
        if (std::isfinite(d)) {
            EXPECT_NEAR(d, 100.0f, 2.5f) << "pixel " << i % kWidth << "," << i / kWidth;
            EXPECT_GE(out.confidence[i], 1);
            ++measured;
        }
        evidence += out.near_field[i] != kNoNearEvidence;
    });
    EXPECT_GT(measured, inside * 3 / 4) << "measured " << measured << " of " << inside;

    // The full level alone cannot: nearer than its range, never a number of the background.
    const Output full = match(pair, settingsFor(false));
    int flagged = 0;
    forEachInside(pair, [&](size_t i) {
        const float d = full.disparity_px[i];
        EXPECT_FALSE(std::isfinite(d) && d < 60.0f) << "a too-far number: " << d;
        flagged += full.near_field[i] == kNearerThanRange;
    });
    EXPECT_GT(flagged, inside / 4);
    EXPECT_LT(evidence, inside / 20);
}

// The coarse level's matches where the full level found none, for the reading: only
// there, and within a coarse pixel of the truth on the rectangle (within the full range:
// not in the depth map).
TEST(PyramidSgmTest, TheCoarseLevelsMatchesWhereTheFullLevelHasNoneAreGivenApart)
{
    const SyntheticPair pair = sceneWith(40);
    const Output out = match(pair, settingsFor(true));
    int given = 0;
    for (size_t i = 0; i < out.disparity_px.size(); ++i) {
        const float coarse = out.coarse_only_px[i];
        ASSERT_NE(coarse, -1.0f) << "pixel " << i << " not written";
        if (std::isfinite(out.disparity_px[i])) {
            EXPECT_FALSE(std::isfinite(coarse)) << "pixel " << i << " has both";
        }
        given += std::isfinite(coarse);
    }
    EXPECT_GT(given, 0);
    forEachInside(pair, [&](size_t i) {
        if (std::isfinite(out.coarse_only_px[i])) {
            EXPECT_NEAR(out.coarse_only_px[i], 40.0f, 2.5f);
        }
    });
}

// Only the reading counts them: outside its region they are not even written.
TEST(PyramidSgmTest, TheCoarseLevelsMatchesAreGivenInTheReadingsRegionAlone)
{
    const SyntheticPair pair = sceneWith(40);
    const PixelRect region{200, 30, 150, 100};
    const Output whole = match(pair, settingsFor(true));
    const Output out = match(pair, settingsFor(true), region);
    int given = 0;
    for (int y = 0; y < pair.height; ++y) {
        for (int x = 0; x < pair.width; ++x) {
            const size_t i = pair.at(x, y);
            const bool inside = x >= region.x && x < region.x + region.width && y >= region.y &&
                                y < region.y + region.height;
            if (!inside) {
                ASSERT_EQ(out.coarse_only_px[i], -1.0f) << "pixel " << x << ", " << y;
                continue;
            }
            const float a = whole.coarse_only_px[i], b = out.coarse_only_px[i];
            ASSERT_TRUE((std::isinf(a) && std::isinf(b)) || a == b) << "pixel " << x << ", " << y;
            given += std::isfinite(b);
        }
    }
    EXPECT_GT(given, 0);
}

TEST(PyramidSgmTest, ASurfaceBeyondTheExtendedRangeIsNearEvidenceNeverANumber)
{
    const SyntheticPair pair = sceneWith(150); // beyond 126
    const Output out = match(pair, settingsFor(true));
    int inside = 0, beyond = 0;
    forEachInside(pair, [&](size_t i) {
        ++inside;
        const float d = out.disparity_px[i];
        EXPECT_FALSE(std::isfinite(d) && d < 120.0f) << "a too-far number: " << d;
        beyond += out.near_field[i] == kNearerThanExtendedRange;
    });
    EXPECT_GT(beyond, inside / 2) << beyond << " of " << inside;
}

TEST(PyramidSgmTest, WithoutTheExtendedRangeTheFullLevelIsCensusSgm)
{
    const SyntheticPair pair = sceneWith(40);
    const PyramidSgmSettings settings = settingsFor(false);
    const Output pyramid = match(pair, settings, PixelRect{});
    CensusSgm core(settings.full);
    const size_t area = pair.left.size();
    Output alone{
        std::vector<float>(area), std::vector<uint8_t>(area), std::vector<uint8_t>(area), {}};
    core.compute(pair.left.data(), kWidth, pair.right.data(), kWidth,
                 {alone.disparity_px.data(), alone.confidence.data(), alone.near_field.data()});
    for (size_t i = 0; i < area; ++i) {
        ASSERT_TRUE(pyramid.disparity_px[i] == alone.disparity_px[i] ||
                    (std::isinf(pyramid.disparity_px[i]) && std::isinf(alone.disparity_px[i])))
            << i;
        ASSERT_EQ(pyramid.confidence[i], alone.confidence[i]) << i;
        ASSERT_EQ(pyramid.near_field[i], alone.near_field[i]) << i;
    }
}

TEST(PyramidSgmTest, SimdAndScalarGiveIdenticalOutput)
{
    for (const bool guided : {false, true})
        for (const int disparity : {40, 100, 150}) {
            SCOPED_TRACE(guided ? "guided" : "full search");
            const SyntheticPair pair = sceneWith(disparity);
            const Output simd = match(pair, settingsFor(true, true, guided));
            const Output scalar = match(pair, settingsFor(true, false, guided));
            for (size_t i = 0; i < pair.left.size(); ++i) {
                ASSERT_TRUE(
                    simd.disparity_px[i] == scalar.disparity_px[i] ||
                    (std::isinf(simd.disparity_px[i]) && std::isinf(scalar.disparity_px[i])))
                    << "disparity " << disparity << ", pixel " << i;
                ASSERT_EQ(simd.confidence[i], scalar.confidence[i]) << disparity << ", " << i;
                ASSERT_EQ(simd.near_field[i], scalar.near_field[i]) << disparity << ", " << i;
            }
        }
}

// The guided search (guided_spans.hpp) on a surface in the full range, beyond it, and
// beyond the extended range: the full search's disparities where both report, searching
// less than the whole range, and never a too-far number.
TEST(PyramidSgmTest, TheGuidedSearchFindsWhatTheFullSearchFinds)
{
    for (const int disparity : {40, 100, 150}) {
        SCOPED_TRACE("rectangle at " + std::to_string(disparity) + " px");
        const SyntheticPair pair = sceneWith(disparity);
        PyramidSgm guided(settingsFor(true, true, true));
        const size_t area = pair.left.size();
        const Output out = computeWith(guided, pair);
        EXPECT_LT(guided.searchedShare(), 0.75);
        const Output full = match(pair, settingsFor(true));
        int both = 0, agree = 0, full_reported = 0, guided_reported = 0;
        for (size_t i = 0; i < area; ++i) {
            const float g = out.disparity_px[i], f = full.disparity_px[i];
            full_reported += std::isfinite(f);
            guided_reported += std::isfinite(g);
            if (std::isfinite(g) && std::isfinite(f)) {
                ++both;
                agree += std::abs(g - f) <= 1.0f;
            }
        }
        EXPECT_GT(agree, both * 99 / 100) << agree << " of " << both;
        EXPECT_GT(guided_reported, full_reported * 9 / 10);
        int inside = 0, near = 0;
        forEachInside(pair, [&](size_t i) {
            ++inside;
            const float d = out.disparity_px[i];
            EXPECT_FALSE(std::isfinite(d) && d < static_cast<float>(disparity) - 3.0f)
                << "a too-far number: " << d;
            near += std::isfinite(d) || out.near_field[i] != kNoNearEvidence;
        });
        EXPECT_GT(near, inside * 3 / 4) << near << " of " << inside;
    }
}

// A frame whose spans would search more than guided_max_share of the lanes searches the
// whole range: what the pyramid without the guided search gives, to the bit.
TEST(PyramidSgmTest, AGuidedFrameThatWouldSearchMostLanesSearchesTheWholeRange)
{
    for (const int disparity : {40, 100}) {
        SCOPED_TRACE("rectangle at " + std::to_string(disparity) + " px");
        const SyntheticPair pair = sceneWith(disparity);
        PyramidSgmSettings capped = settingsFor(true, true, true);
        capped.guided_max_share = 0.4; // two vectors of lanes: a span is half of them at least
        PyramidSgm guided(capped);
        const Output out = computeWith(guided, pair);
        EXPECT_EQ(guided.searchedShare(), 1.0);
        const Output full = match(pair, settingsFor(true));
        for (size_t i = 0; i < pair.left.size(); ++i) {
            ASSERT_TRUE(out.disparity_px[i] == full.disparity_px[i] ||
                        (std::isinf(out.disparity_px[i]) && std::isinf(full.disparity_px[i])))
                << i;
            ASSERT_EQ(out.confidence[i], full.confidence[i]) << i;
            ASSERT_EQ(out.near_field[i], full.near_field[i]) << i;
        }
    }
    PyramidSgmSettings wrong = settingsFor(true, true, true);
    wrong.guided_max_share = 1.5;
    EXPECT_THROW(validatePyramidSgmSettings(wrong), std::invalid_argument);
}

TEST(PyramidSgmTest, TheLevelsRanges)
{
    PyramidSgm extended(settingsFor(true));
    EXPECT_EQ(extended.fullRangeLast(), 63);
    EXPECT_EQ(extended.extendedRangeLast(), 126);
    PyramidSgm full(settingsFor(false));
    EXPECT_EQ(full.extendedRangeLast(), 63);
    // A negative first disparity halves downwards, so the coarse range covers the full one.
    PyramidSgmSettings negative = settingsFor(true);
    negative.full.min_disparity = -5;
    const CensusSgmSettings coarse = coarseLevelSettings(negative.full);
    EXPECT_EQ(coarse.min_disparity, -3);
    EXPECT_EQ(coarse.width, kWidth / 2);
    EXPECT_EQ(coarse.num_disparities, kNumDisparities);
}

TEST(PyramidSgmTest, RefusesAnImageTooSmallForTheCoarseLevel)
{
    PyramidSgmSettings s = settingsFor(true);
    s.full.width = 9;
    s.full.height = 2;
    EXPECT_THROW(validatePyramidSgmSettings(s), std::invalid_argument);
    s.extended_range = false;
    s.full.width = 16;
    EXPECT_NO_THROW(validatePyramidSgmSettings(s));
}

// The halving, the merge and the probe shared out over threads give what one thread gives,
// bit for bit, with the extended range measuring a surface beyond the full range. (Past
// the extended range, at 140 px, 4 pixels differ with the thread count in the levels' own
// matches already, with the merge and the probe on one thread.)
TEST(PyramidSgmTest, ThreadsGiveWhatOneThreadGives)
{
    const SyntheticPair pair = sceneWith(100);
    PyramidSgmSettings one = settingsFor(true);
    one.full.threads = 1;
    PyramidSgmSettings two = one;
    two.full.threads = 2;
    const Output a = match(pair, one), b = match(pair, two);
    EXPECT_EQ(a.near_field, b.near_field);
    EXPECT_EQ(a.confidence, b.confidence);
    size_t differ = 0;
    const auto same = [](float x, float y) { return (std::isinf(x) && std::isinf(y)) || x == y; };
    for (size_t i = 0; i < a.disparity_px.size(); ++i)
        differ += !same(a.disparity_px[i], b.disparity_px[i]) ||
                  !same(a.coarse_only_px[i], b.coarse_only_px[i]);
    EXPECT_EQ(differ, 0u);
}

// The full level's match of the pair, for the probe to read its census images.
void matchFullLevel(const SyntheticPair& pair, CensusSgm& core)
{
    const size_t area = pair.left.size();
    std::vector<float> d(area);
    std::vector<uint8_t> c(area), r(area);
    core.compute(pair.left.data(), kWidth, pair.right.data(), kWidth,
                 {d.data(), c.data(), r.data()});
}

// The probe alone, on the full level's census: a textured surface beyond the range marks
// the tiles on it and nothing else; a scene within the range marks none.
TEST(NearFieldProbeTest, MarksTheTilesOfASurfaceBeyondTheRangeOnly)
{
    for (const int disparity : {20, 90}) {
        const SyntheticPair pair = sceneWith(disparity);
        CensusSgm core(settingsFor(false).full);
        matchFullLevel(pair, core);
        NearFieldProbe probe(kWidth, kHeight);
        probe.run(pair.left.data(), kWidth, core, kWholeImage, 0, kNumDisparities - 1);
        EXPECT_GT(probe.probedTiles(), 100);
        int on = 0, off = 0;
        for (const PixelRect& tile : probe.evidenceTiles()) {
            const int cx = tile.x + tile.width / 2, cy = tile.y + tile.height / 2;
            const bool on_surface = cx >= 230 && cx < 330 && cy >= 40 && cy < 120;
            (on_surface ? on : off) += 1;
        }
        if (disparity == 20) {
            EXPECT_EQ(on + off, 0) << "a scene within the range gives no evidence";
        } else {
            EXPECT_GE(on, 60) << "of the 12 x 10 tiles on the surface";
            EXPECT_EQ(off, 0);
        }
    }
}

// Rows of tiles shared out over a pool's threads give the tiles one thread gives, in the
// same order, with the same count of probed tiles.
TEST(NearFieldProbeTest, ThreadsFindWhatOneThreadFinds)
{
    const SyntheticPair pair = sceneWith(90);
    CensusSgm core(settingsFor(false).full);
    matchFullLevel(pair, core);
    NearFieldProbe alone(kWidth, kHeight);
    alone.run(pair.left.data(), kWidth, core, kWholeImage, 0, kNumDisparities - 1);
    ASSERT_FALSE(alone.evidenceTiles().empty());
    for (const int threads : {2, 3}) {
        BandPool pool(threads);
        NearFieldProbe shared(kWidth, kHeight, NearFieldProbeSettings{}, threads);
        shared.run(pair.left.data(), kWidth, core, kWholeImage, 0, kNumDisparities - 1, &pool);
        EXPECT_EQ(shared.probedTiles(), alone.probedTiles()) << threads << " threads";
        ASSERT_EQ(shared.evidenceTiles().size(), alone.evidenceTiles().size()) << threads;
        for (size_t i = 0; i < alone.evidenceTiles().size(); ++i) {
            EXPECT_EQ(shared.evidenceTiles()[i].x, alone.evidenceTiles()[i].x);
            EXPECT_EQ(shared.evidenceTiles()[i].y, alone.evidenceTiles()[i].y);
        }
    }
}

} // namespace
} // namespace stereod::sgm
