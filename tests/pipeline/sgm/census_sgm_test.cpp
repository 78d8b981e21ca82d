// The whole census + semi-global matcher on a synthetic stereo pair with known
// disparities (synthetic_pair.hpp): SIMD against the scalar reference, accuracy against
// the ground truth, two bands against one, the left edge where the search is cut, and
// the settings it refuses.

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/sgm/census_sgm.hpp"
#include "pipeline/sgm/gap_bridge.hpp"
#include "tests/pipeline/sgm/synthetic_pair.hpp"

namespace stereod::sgm {
namespace {

using test::makeSyntheticPair;
using test::SyntheticPair;

struct Output {
    std::vector<float> disparity_px;
    std::vector<uint8_t> confidence;
    std::vector<uint8_t> range_limit;

    bool valid(size_t i) const { return std::isfinite(disparity_px[i]); }
};

Output match(const SyntheticPair& pair, const CensusSgmSettings& settings)
{
    CensusSgmSettings s = settings;
    s.width = pair.width;
    s.height = pair.height;
    CensusSgm matcher(s);
    const size_t area = pair.left.size();
    Output out{std::vector<float>(area, -1.0f), std::vector<uint8_t>(area, 77),
               std::vector<uint8_t>(area, 77)};
    const auto stride = static_cast<size_t>(pair.width);
    matcher.compute(
        pair.left.data(), stride, pair.right.data(), stride,
        CensusSgmOutput{out.disparity_px.data(), out.confidence.data(), out.range_limit.data()});
    return out;
}

// The scene: a background at 10 px; rectangles nearer, at 24 px and 40 px; one at the
// near end of the searched range 0..63 (63 px) and one nearer than the range (90 px).
// Left of x = 63 the search is cut by the image edge.
constexpr int kNumDisparities = 64;
struct Rect {
    int x0, y0, x1, y1;
};
constexpr Rect kAtNearEnd{165, 4, 215, 48}; // 63 px
constexpr Rect kTooNear{100, 66, 150, 104}; // 90 px

const SyntheticPair& scene()
{
    static const SyntheticPair pair = makeSyntheticPair(
        224, 112,
        {{-1000, 0, 1224, 112, 10},
         {90, 10, 150, 50, 24},
         {160, 56, 215, 100, 40},
         {kAtNearEnd.x0, kAtNearEnd.y0, kAtNearEnd.x1, kAtNearEnd.y1, kNumDisparities - 1},
         {kTooNear.x0, kTooNear.y0, kTooNear.x1, kTooNear.y1, 90}},
        7);
    return pair;
}

CensusSgmSettings sceneSettings()
{
    CensusSgmSettings s;
    s.num_disparities = kNumDisparities;
    return s;
}

// The planar tuning (kPlanarSceneSettings): P2 at full height across edges, a low
// uniqueness margin, the texture check and short gaps bridged.
CensusSgmSettings planarSettings()
{
    CensusSgmSettings s = kPlanarSceneSettings;
    s.num_disparities = kNumDisparities;
    return s;
}

// The patterns tuning's (natural, planar's steps inside repeating patterns).
CensusSgmSettings patternSettings()
{
    CensusSgmSettings s = kPatternSceneSettings;
    s.num_disparities = kNumDisparities;
    return s;
}

// The default settings' output on the scene, computed once for the tests that only read it.
const Output& sceneOutput()
{
    static const Output out = match(scene(), sceneSettings());
    return out;
}

// Whether the census window around (x, y), one pixel wider for the 3x3 median, reaches
// another surface: there the window matches both surfaces in part, and either disparity
// is a fair answer.
bool nearDepthEdge(const SyntheticPair& pair, int x, int y)
{
    const CensusSgmSettings s = sceneSettings();
    const int rx = s.census_width / 2 + 1, ry = s.census_height / 2 + 1;
    const int truth = pair.truth_px[pair.at(x, y)];
    for (int v = std::max(0, y - ry); v <= std::min(pair.height - 1, y + ry); ++v)
        for (int u = std::max(0, x - rx); u <= std::min(pair.width - 1, x + rx); ++u)
            if (pair.truth_px[pair.at(u, v)] != truth)
                return true;
    return false;
}

// Where the ground truth can be held against a disparity: the search is not cut by the
// edge, the surface lies inside the range short of its near end (which is flagged, not
// measured), the right view sees it, and it is not next to another surface.
bool comparable(const SyntheticPair& pair, int x, int y)
{
    const size_t i = pair.at(x, y);
    return x >= kNumDisparities - 1 && pair.truth_px[i] < kNumDisparities - 1 &&
           pair.occluded[i] == 0 && !nearDepthEdge(pair, x, y);
}

bool bitIdentical(const std::vector<float>& a, const std::vector<float>& b)
{
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](float x, float y) {
               return std::bit_cast<uint32_t>(x) == std::bit_cast<uint32_t>(y);
           });
}

TEST(CensusSgmTest, SimdAndScalarGiveIdenticalOutput)
{
    CensusSgmSettings narrow = sceneSettings(); // a shifted range, three paths
    narrow.min_disparity = -8;
    narrow.num_disparities = 32;
    narrow.paths = 3;
    CensusSgmSettings wide = sceneSettings(); // a positive start, the widest census
    wide.min_disparity = 5;
    wide.num_disparities = 48;
    wide.census_width = 9;
    wide.census_height = 7;
    wide.p2 = 150;
    // A smaller pair than the scene: the scalar reference is slow under the sanitizers.
    const SyntheticPair pair = makeSyntheticPair(
        160, 64, {{-1000, 0, 1160, 64, 6}, {70, 8, 120, 40, 20}, {20, 30, 60, 60, 45}}, 3);
    for (const CensusSgmSettings& base :
         {sceneSettings(), narrow, wide, planarSettings(), patternSettings()})
        for (int threads : {1, 2}) {
            SCOPED_TRACE("min_disparity " + std::to_string(base.min_disparity) + ", threads " +
                         std::to_string(threads));
            CensusSgmSettings simd = base;
            simd.threads = threads;
            simd.use_simd = true;
            CensusSgmSettings scalar = simd;
            scalar.use_simd = false;
            const Output a = match(pair, simd);
            const Output b = match(pair, scalar);
            // Not two empty maps: most of the pair is matched.
            const auto matched = std::count_if(a.disparity_px.begin(), a.disparity_px.end(),
                                               [](float d) { return std::isfinite(d); });
            EXPECT_GT(matched * 2, static_cast<long>(a.disparity_px.size()));
            EXPECT_TRUE(bitIdentical(a.disparity_px, b.disparity_px));
            EXPECT_EQ(a.confidence, b.confidence);
            EXPECT_EQ(a.range_limit, b.range_limit);
        }
}

// Gaps bridged (gap_fill_px): the matched pixels stay as they were, the bridged ones say
// they were inferred and lie on the surface they span: none spans a depth edge, whose
// two sides disagree. (Next to an edge the matcher's own disparities may belong to either
// side, and so may a line between them; the surfaces nearer than the range are held to
// "no number deep inside" below.)
TEST(CensusSgmTest, BridgedGapsAddOnlyInferredPixelsOnTheSurface)
{
    CensusSgmSettings bridging = sceneSettings();
    bridging.gap_fill_px = 15;
    const Output& matched = sceneOutput();
    const Output bridged = match(scene(), bridging);
    const SyntheticPair& pair = scene();
    int added = 0, compared = 0, off = 0;
    for (size_t i = 0; i < pair.truth_px.size(); ++i) {
        if (matched.valid(i)) {
            ASSERT_EQ(std::bit_cast<uint32_t>(bridged.disparity_px[i]),
                      std::bit_cast<uint32_t>(matched.disparity_px[i]))
                << "pixel " << i;
            ASSERT_EQ(bridged.confidence[i], matched.confidence[i]) << "pixel " << i;
            continue;
        }
        if (!bridged.valid(i))
            continue;
        ++added;
        EXPECT_EQ(bridged.confidence[i], kInferredConfidence) << "pixel " << i;
        const int x = static_cast<int>(i) % pair.width, y = static_cast<int>(i) / pair.width;
        if (!comparable(pair, x, y))
            continue;
        ++compared;
        off += std::abs(bridged.disparity_px[i] - static_cast<float>(pair.truth_px[i])) > 1.0f;
    }
    // Most gaps of a textured scene lie at its depth edges; a few inside its surfaces.
    EXPECT_GT(added, 200);
    EXPECT_GT(compared, 20) << "little bridged inside a surface: the test would prove little";
    EXPECT_EQ(off, 0) << off << " of " << compared << " bridged pixels more than 1 px off";
}

TEST(CensusSgmTest, TargetNamesTheKernels)
{
    CensusSgmSettings s = sceneSettings();
    s.width = 64;
    s.height = 16;
    s.use_simd = false;
    EXPECT_STREQ(CensusSgm(s).target(), "scalar");
    s.use_simd = true;
    EXPECT_STREQ(CensusSgm(s).target(), simdKernels().target);
}

TEST(CensusSgmAccuracyTest, MostPixelsWithinHalfPixelOfTruth)
{
    const SyntheticPair& pair = scene();
    const Output& out = sceneOutput();
    int compared = 0, good = 0;
    for (int y = 0; y < pair.height; ++y)
        for (int x = 0; x < pair.width; ++x) {
            if (!comparable(pair, x, y))
                continue;
            const size_t i = pair.at(x, y);
            ++compared;
            if (out.valid(i) &&
                std::abs(out.disparity_px[i] - static_cast<float>(pair.truth_px[i])) <= 0.5f)
                ++good;
        }
    ASSERT_GT(compared, 5000);
    EXPECT_GE(good * 100, compared * 97) << good << " of " << compared << " pixels within 0.5 px";
}

// Too far (a disparity more than 1 px below the truth) is the dangerous error for a robot:
// an obstacle reads farther than it is.
TEST(CensusSgmAccuracyTest, NoValidPixelFartherThanTruthOutsideOcclusions)
{
    const SyntheticPair& pair = scene();
    const Output& out = sceneOutput();
    int too_far = 0;
    std::string where; // the first few
    for (int y = 0; y < pair.height; ++y)
        for (int x = 0; x < pair.width; ++x) {
            const size_t i = pair.at(x, y);
            if (pair.occluded[i] != 0 || !out.valid(i) || nearDepthEdge(pair, x, y))
                continue;
            if (out.disparity_px[i] < static_cast<float>(pair.truth_px[i]) - 1.0f && too_far++ < 10)
                where += " (" + std::to_string(x) + ", " + std::to_string(y) +
                         "): " + std::to_string(out.disparity_px[i]) + " px, truth " +
                         std::to_string(pair.truth_px[i]) + " px;";
        }
    EXPECT_EQ(too_far, 0) << "too far at" << where;
}

struct RectCount {
    int pixels = 0, valid = 0, flagged = 0;
    std::string valid_at; // the first few valid pixels
};

// Counts over the rectangle shrunk by `inset` pixels on every side.
RectCount countInside(const SyntheticPair& pair, const Output& out, const Rect& r, int inset)
{
    RectCount c;
    for (int y = r.y0 + inset; y < r.y1 - inset; ++y)
        for (int x = r.x0 + inset; x < r.x1 - inset; ++x) {
            const size_t i = pair.at(x, y);
            ++c.pixels;
            c.flagged += out.range_limit[i] != 0 ? 1 : 0;
            if (out.valid(i) && c.valid++ < 10)
                c.valid_at += " (" + std::to_string(x) + ", " + std::to_string(y) +
                              "): " + std::to_string(out.disparity_px[i]) + " px;";
        }
    return c;
}

// A surface at the near end of the range (63 px): the best match sits on the last
// disparity, so it may be nearer still; flagged, and no number given.
TEST(CensusSgmAccuracyTest, SurfaceAtNearEndOfRangeIsFlaggedNotMeasured)
{
    const RectCount c = countInside(scene(), sceneOutput(), kAtNearEnd, 4);
    EXPECT_EQ(c.valid, 0) << "valid at" << c.valid_at;
    EXPECT_GE(c.flagged * 100, c.pixels * 99) << c.flagged << " of " << c.pixels << " flagged";
}

// A 60 x 60 px surface nearer than the searched range 0..63, in front of the background
// at 10 px.
constexpr Rect kNearSurface{100, 30, 160, 90};
constexpr int kNearerThanRange[] = {64, 70, 90, 120};

SyntheticPair nearSurfacePair(int disparity_px)
{
    return makeSyntheticPair(
        224, 112,
        {{-1000, 0, 1224, 112, 10},
         {kNearSurface.x0, kNearSurface.y0, kNearSurface.x1, kNearSurface.y1, disparity_px}},
        7);
}

// A surface nearer than the range has no match: no number deep inside it (the paths
// carry the background's disparity some pixels in from its edges; see below).
TEST(CensusSgmAccuracyTest, SurfaceNearerThanRangeReadsNoNumberDeepInside)
{
    for (int d : kNearerThanRange)
        for (const CensusSgmSettings& settings :
             {sceneSettings(), planarSettings(), patternSettings()}) {
            SCOPED_TRACE("surface at " + std::to_string(d) + " px, P2 adapted by " +
                         std::to_string(settings.p2_gradient_scale) + ", patterns " +
                         std::to_string(settings.periodic_patterns));
            const SyntheticPair pair = nearSurfacePair(d);
            const RectCount c = countInside(pair, match(pair, settings), kNearSurface, 10);
            EXPECT_EQ(c.valid, 0) << "valid at" << c.valid_at;
        }
}

// P2 at full height across edges carries the disparity around a surface into it, also
// where the surface is nearer than the range and has no match; only the texture check
// stands in the way.
TEST(CensusSgmAccuracyTest, WithoutTheTextureCheckFullHeightPathsReadIntoANearerSurface)
{
    CensusSgmSettings unchecked = planarSettings();
    unchecked.textured_max_cost = -1;
    const SyntheticPair pair = nearSurfacePair(kNearerThanRange[0]);
    const RectCount c = countInside(pair, match(pair, unchecked), kNearSurface, 10);
    EXPECT_GT(c.valid, 100);
}

TEST(CensusSgmAccuracyTest, RangeLimitFlagsOnlyInvalidPixels)
{
    const Output& out = sceneOutput();
    for (size_t i = 0; i < out.range_limit.size(); ++i) {
        ASSERT_LE(out.range_limit[i], 1) << "pixel " << i;
        if (out.range_limit[i] != 0) {
            ASSERT_FALSE(out.valid(i))
                << "pixel " << i << " is flagged but reads " << out.disparity_px[i] << " px";
        }
        ASSERT_EQ(out.confidence[i] == 0, !out.valid(i)) << "pixel " << i;
    }
}

struct BandComparison {
    int differing = 0;
    int worst_row = -1;
    int worst_row_differing = 0;
};

BandComparison compareOneAndTwoBands()
{
    const SyntheticPair& pair = scene();
    CensusSgmSettings two = sceneSettings();
    two.threads = 2;
    const Output& a = sceneOutput();
    const Output b = match(pair, two);
    BandComparison c;
    for (int y = 0; y < pair.height; ++y) {
        int row = 0;
        for (int x = 0; x < pair.width; ++x) {
            const size_t i = pair.at(x, y);
            const bool same =
                a.valid(i) == b.valid(i) && (!a.valid(i) || a.disparity_px[i] == b.disparity_px[i]);
            row += same ? 0 : 1;
        }
        c.differing += row;
        if (row > c.worst_row_differing) {
            c.worst_row_differing = row;
            c.worst_row = y;
        }
    }
    return c;
}

TEST(CensusSgmThreadsTest, TwoBandsMatchOneBand)
{
    const BandComparison c = compareOneAndTwoBands();
    const int area = scene().width * scene().height;
    EXPECT_LE(c.differing * 1000, area * 5) << c.differing << " of " << area << " pixels differ";
}

TEST(CensusSgmThreadsTest, NoDifferencesConcentratedAtBandSeam)
{
    // The second band starts at row height / 2; its paths from above start 32 rows
    // earlier, so that no row there differs much from a single band's.
    const BandComparison c = compareOneAndTwoBands();
    EXPECT_LE(c.worst_row_differing * 100, scene().width * 2)
        << c.worst_row_differing << " pixels differ in row " << c.worst_row << " (seam at row "
        << scene().height / 2 << ")";
}

// The left band, x < min_disparity + num_disparities - 1, where the right image ends
// before the search does. No disparity may point past the right image's first column
// (x - d >= 0); and a kept one lies edge_margin_px below the cut, give or take half a
// pixel of sub-pixel offset and one column that the 3x3 median may bring in from the
// right-hand neighbour.
void expectCutSearchWithinColumn(int min_disparity, int edge_margin_px)
{
    SCOPED_TRACE("min_disparity " + std::to_string(min_disparity) + ", edge_margin_px " +
                 std::to_string(edge_margin_px));
    // A background at 40 px, whose pixels left of x = 40 have no match at all, and a
    // rectangle at 20 px inside the cut band.
    const SyntheticPair pair =
        makeSyntheticPair(160, 64, {{-1000, 0, 1160, 64, 40}, {10, 16, 50, 48, 20}}, 11);
    CensusSgmSettings s = sceneSettings();
    s.min_disparity = min_disparity;
    s.edge_margin_px = edge_margin_px;
    const Output out = match(pair, s);
    const int cut = min_disparity + s.num_disparities - 1;
    int valid = 0, past_edge = 0, past_margin = 0;
    std::string where; // the first few
    for (int y = 0; y < pair.height; ++y)
        for (int x = 0; x < std::min(cut, pair.width); ++x) {
            const size_t i = pair.at(x, y);
            if (!out.valid(i))
                continue;
            ++valid;
            const float d = out.disparity_px[i];
            const bool beyond_edge = d > static_cast<float>(x);
            const bool beyond_margin = d > static_cast<float>(x - edge_margin_px) + 1.5f;
            past_edge += beyond_edge ? 1 : 0;
            past_margin += beyond_margin ? 1 : 0;
            if ((beyond_edge || beyond_margin) && past_margin + past_edge <= 10)
                where += " (" + std::to_string(x) + ", " + std::to_string(y) +
                         "): " + std::to_string(d) + " px;";
        }
    EXPECT_GT(valid, 0) << "the rectangle in the cut band should be matched";
    EXPECT_EQ(past_edge, 0) << "pointing past the right image's first column:" << where;
    EXPECT_EQ(past_margin, 0) << "within edge_margin_px of the cut:" << where;
}

TEST(CensusSgmEdgeTest, CutSearchNeverExceedsColumn)
{
    expectCutSearchWithinColumn(0, 4);
    expectCutSearchWithinColumn(5, 4);
    expectCutSearchWithinColumn(-3, 4);
}

// Without a margin the sub-pixel parabola at the last searchable lane must not use the
// next lane, whose right pixel lies outside the image.
TEST(CensusSgmEdgeTest, CutSearchWithoutMarginNeverExceedsColumn)
{
    expectCutSearchWithinColumn(0, 0);
    expectCutSearchWithinColumn(5, 0);
}

// Whether message names `key` as a whole word (e.g. "p2", not the "p2" in
// "p2_gradient_scale").
bool namesKey(const std::string& message, const std::string& key)
{
    const auto word = [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
    };
    for (size_t at = message.find(key); at != std::string::npos; at = message.find(key, at + 1)) {
        const bool starts = at == 0 || !word(message[at - 1]);
        const bool ends = at + key.size() == message.size() || !word(message[at + key.size()]);
        if (starts && ends)
            return true;
    }
    return false;
}

void expectRejected(const CensusSgmSettings& settings, const std::string& key)
{
    try {
        CensusSgm matcher(settings);
        ADD_FAILURE() << "accepted; expected std::invalid_argument naming " << key;
    } catch (const std::invalid_argument& e) {
        EXPECT_TRUE(namesKey(e.what(), key)) << "'" << e.what() << "' does not name " << key;
    }
}

CensusSgmSettings smallSettings()
{
    CensusSgmSettings s;
    s.width = 64;
    s.height = 32;
    return s;
}

TEST(CensusSgmSettingsTest, AcceptsDefaultsAndTheLargestP2)
{
    EXPECT_NO_THROW(validateCensusSgmSettings(smallSettings()));
    CensusSgmSettings s = smallSettings();
    s.census_width = 9;
    s.census_height = 7;
    s.p2 = 255 - 62; // census cost 62 + p2 = 255, the most 8-bit path costs allow
    EXPECT_NO_THROW(validateCensusSgmSettings(s));
}

TEST(CensusSgmSettingsTest, RejectsNumDisparitiesNotMultipleOf16)
{
    CensusSgmSettings s = smallSettings();
    s.num_disparities = 40;
    expectRejected(s, "num_disparities");
}

TEST(CensusSgmSettingsTest, RejectsEvenCensusSide)
{
    CensusSgmSettings s = smallSettings();
    s.census_width = 6;
    expectRejected(s, "census");
    s = smallSettings();
    s.census_height = 4;
    expectRejected(s, "census");
}

TEST(CensusSgmSettingsTest, RejectsP2NotAboveP1)
{
    CensusSgmSettings s = smallSettings();
    s.p1 = 20;
    s.p2 = 20;
    expectRejected(s, "p2");
}

TEST(CensusSgmSettingsTest, RejectsCensusBitsPlusP2Over255)
{
    CensusSgmSettings s = smallSettings();
    s.census_width = 9;
    s.census_height = 7;
    s.p2 = 255 - 62 + 1;
    expectRejected(s, "p2");
}

TEST(CensusSgmSettingsTest, RejectsANegativeGap)
{
    CensusSgmSettings s = smallSettings();
    s.gap_fill_px = -1;
    expectRejected(s, "gap_fill_px");
}

TEST(CensusSgmSettingsTest, RejectsATextureCheckBeyondTheCensusBits)
{
    CensusSgmSettings s = smallSettings();
    s.textured_max_cost = 33; // 11x3: 32 bits
    expectRejected(s, "textured_max_cost");
    s.textured_max_cost = 8;
    s.textured_min_range = 256;
    expectRejected(s, "textured_min_range");
}

TEST(CensusSgmSettingsTest, RejectsPatternStepsOutOfRange)
{
    CensusSgmSettings s = smallSettings();
    s.periodic_uniqueness_percent = 101;
    expectRejected(s, "periodic_uniqueness_percent");
    s = smallSettings();
    s.periodic_textured_max_cost = 33; // 11x3: 32 bits
    expectRejected(s, "periodic_textured_max_cost");
    s = smallSettings();
    s.periodic_gap_fill_px = -1;
    expectRejected(s, "periodic_gap_fill_px");
}

TEST(CensusSgmSettingsTest, RejectsZeroThreads)
{
    CensusSgmSettings s = smallSettings();
    s.threads = 0;
    expectRejected(s, "threads");
}

} // namespace
} // namespace stereod::sgm
