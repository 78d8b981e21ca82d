// The verdict of a reading as a table: each row sets facts and names the reading they must
// give, so that the precedence written once in judgeReading() is held row by row; then the
// fields the verdict carries (bounds, fractions, the calibration flag).

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/reading_verdict.hpp"

namespace stereod {
namespace {

// A processed pair whose region gives a valid 1.25 m: every row starts from it.
ReadingFacts goodPair()
{
    ReadingFacts f;
    f.pair = PairOutcome::Processed;
    f.stamp_ns = 7'000'000;
    f.frame = 42;
    f.region.region_pixels = 10000;
    f.region.valid_pixels = 6000;
    f.region.in_range_pixels = 5000;
    f.region.percentile_depth_m = 1.25;
    f.min_valid_fraction = 0.10;
    f.min_pixels = 50;
    f.min_in_range_fraction = 0.05;
    f.near_evidence_fraction = 0.02;
    f.near_field = {true, 0.45, 0.225};
    f.max_skew_ms = 10.0;
    f.max_age_ms = 500.0;
    return f;
}

struct Row {
    std::string what;
    void (*set)(ReadingFacts&);
    NoReadingReason expected;
};

const std::vector<Row> kTable = {
    {"a good pair", [](ReadingFacts&) {}, NoReadingReason::None},
    // Each fact alone.
    {"uncalibrated", [](ReadingFacts& f) { f.calibrated = false; }, NoReadingReason::Uncalibrated},
    {"source down", [](ReadingFacts& f) { f.source_down = true; }, NoReadingReason::SourceDown},
    {"no pair yet", [](ReadingFacts& f) { f.pair = PairOutcome::None; },
     NoReadingReason::NoFrameYet},
    {"stale", [](ReadingFacts& f) { f.age_ms = 501.0; }, NoReadingReason::Stale},
    {"bad frame", [](ReadingFacts& f) { f.pair = PairOutcome::BadFrame; },
     NoReadingReason::BadFrame},
    {"out of sync", [](ReadingFacts& f) { f.skew_ms = 10.5; }, NoReadingReason::OutOfSync},
    {"calibration failed, withheld",
     [](ReadingFacts& f) {
         f.calibration_suspect = f.calibration_failed = f.withhold_when_failed = true;
     },
     NoReadingReason::CalibrationSuspect},
    {"calibration failed, not withheld: flagged only",
     [](ReadingFacts& f) { f.calibration_suspect = f.calibration_failed = true; },
     NoReadingReason::None},
    {"calibration degraded: flagged only", [](ReadingFacts& f) { f.calibration_suspect = true; },
     NoReadingReason::None},
    {"near evidence beyond the extended range",
     [](ReadingFacts& f) {
         f.region.nearer_than_range_pixels = f.region.nearer_than_extended_pixels = 200;
     },
     NoReadingReason::NearerThanRange},
    {"near evidence beyond the full range",
     [](ReadingFacts& f) { f.region.nearer_than_range_pixels = 200; },
     NoReadingReason::NearerThanRange},
    {"near evidence below the region's share",
     [](ReadingFacts& f) { f.region.nearer_than_range_pixels = 199; }, NoReadingReason::None},
    {"near evidence below min_pixels",
     [](ReadingFacts& f) {
         f.region.region_pixels = 1000;
         f.region.nearer_than_range_pixels = 49;
         f.region.valid_pixels = 600;
         f.region.in_range_pixels = 500;
     },
     NoReadingReason::None},
    {"too few valid pixels", [](ReadingFacts& f) { f.region.valid_pixels = 999; },
     NoReadingReason::TooFewValidPixels},
    {"no valid pixel at all",
     [](ReadingFacts& f) {
         f.region.valid_pixels = 0;
         f.min_valid_fraction = 0.0;
     },
     NoReadingReason::TooFewValidPixels},
    {"fewer in range than min_pixels", [](ReadingFacts& f) { f.region.in_range_pixels = 49; },
     NoReadingReason::NothingInRange},
    {"a sliver in range", [](ReadingFacts& f) { f.region.in_range_pixels = 499; },
     NoReadingReason::NothingInRange},
    // Precedence: the first reason of the list wins over every later one.
    {"uncalibrated over source down",
     [](ReadingFacts& f) {
         f.calibrated = false;
         f.source_down = true;
     },
     NoReadingReason::Uncalibrated},
    {"source down over stale",
     [](ReadingFacts& f) {
         f.source_down = true;
         f.age_ms = 1e6;
     },
     NoReadingReason::SourceDown},
    {"stale over bad frame",
     [](ReadingFacts& f) {
         f.age_ms = 1e6;
         f.pair = PairOutcome::BadFrame;
     },
     NoReadingReason::Stale},
    {"bad frame over out of sync",
     [](ReadingFacts& f) {
         f.pair = PairOutcome::BadFrame;
         f.skew_ms = 1e3;
     },
     NoReadingReason::BadFrame},
    {"out of sync over a withheld calibration",
     [](ReadingFacts& f) {
         f.skew_ms = 1e3;
         f.calibration_suspect = f.calibration_failed = f.withhold_when_failed = true;
     },
     NoReadingReason::OutOfSync},
    {"a withheld calibration over near evidence and too few pixels",
     [](ReadingFacts& f) {
         f.calibration_suspect = f.calibration_failed = f.withhold_when_failed = true;
         f.region.nearer_than_range_pixels = 5000;
         f.region.valid_pixels = 10;
     },
     NoReadingReason::CalibrationSuspect},
    {"near evidence over too few valid pixels (a near surface matches nothing)",
     [](ReadingFacts& f) {
         f.region.nearer_than_range_pixels = 5000;
         f.region.valid_pixels = 10;
         f.region.in_range_pixels = 10;
     },
     NoReadingReason::NearerThanRange},
    {"too few valid pixels over nothing in range",
     [](ReadingFacts& f) {
         f.region.valid_pixels = 500;
         f.region.in_range_pixels = 0;
     },
     NoReadingReason::TooFewValidPixels},
};

TEST(ReadingVerdict, EveryRowOfTheTable)
{
    for (const Row& row : kTable) {
        ReadingFacts facts = goodPair();
        row.set(facts);
        const Reading reading = judgeReading(facts);
        EXPECT_EQ(reading.reason, row.expected)
            << row.what << ": got " << reasonCode(reading.reason) << ", expected "
            << reasonCode(row.expected);
        EXPECT_EQ(reading.valid, row.expected == NoReadingReason::None) << row.what;
        if (!reading.valid) {
            EXPECT_EQ(reading.distance_m, 0.0) << row.what << ": a refused reading has no number";
        }
    }
}

TEST(ReadingVerdict, AValidReadingCarriesThePercentileAndTheRegion)
{
    const Reading r = judgeReading(goodPair());
    ASSERT_TRUE(r.valid);
    EXPECT_DOUBLE_EQ(r.distance_m, 1.25);
    EXPECT_EQ(r.stamp_ns, 7'000'000);
    EXPECT_EQ(r.frame, 42u);
    EXPECT_DOUBLE_EQ(r.valid_fraction, 0.6);
    EXPECT_DOUBLE_EQ(r.in_range_fraction, 0.5);
    EXPECT_EQ(r.region_pixels, 10000u);
    EXPECT_DOUBLE_EQ(r.closest_m, 0.225);
    EXPECT_TRUE(r.near_field_guard);
    EXPECT_FALSE(r.calibration_suspect);
}

// The share of the region that cannot see as near as the distance (the image's left edge)
// qualifies a number: a valid reading carries it, a refusal has no number to qualify.
TEST(ReadingVerdict, TheLeftEdgesShareQualifiesANumberOnly)
{
    ReadingFacts facts = goodPair();
    facts.region.out_of_view_pixels = 1100;
    Reading r = judgeReading(facts);
    ASSERT_TRUE(r.valid);
    EXPECT_DOUBLE_EQ(r.out_of_view_fraction, 0.11);
    EXPECT_DOUBLE_EQ(r.distance_m, 1.25) << "a caveat, the number stays";

    facts.region.nearer_than_range_pixels = 300;
    r = judgeReading(facts);
    EXPECT_EQ(r.reason, NoReadingReason::NearerThanRange);
    EXPECT_EQ(r.out_of_view_fraction, 0.0);
}

TEST(ReadingVerdict, NearerThanRangeNamesTheBoundOfItsEvidence)
{
    ReadingFacts facts = goodPair();
    facts.region.nearer_than_range_pixels = 300;
    Reading r = judgeReading(facts);
    EXPECT_EQ(r.reason, NoReadingReason::NearerThanRange);
    EXPECT_DOUBLE_EQ(r.nearer_than_m, 0.45) << "evidence beyond the full range only";
    EXPECT_DOUBLE_EQ(r.range_limit_fraction, 0.03);

    facts.region.nearer_than_extended_pixels = 250;
    r = judgeReading(facts);
    EXPECT_EQ(r.reason, NoReadingReason::NearerThanRange);
    EXPECT_DOUBLE_EQ(r.nearer_than_m, 0.225) << "evidence beyond the extended range";
}

TEST(ReadingVerdict, TheCalibrationFlagTravelsWithEveryProcessedPair)
{
    ReadingFacts facts = goodPair();
    facts.calibration_suspect = true;
    facts.calibration_row_offset_px = 1.2;
    Reading r = judgeReading(facts);
    EXPECT_TRUE(r.valid);
    EXPECT_TRUE(r.calibration_suspect);
    EXPECT_DOUBLE_EQ(r.calibration_row_offset_px, 1.2);
    // A no-reading from the data keeps it too: the data came through the suspect rows.
    facts.region.valid_pixels = 1;
    r = judgeReading(facts);
    EXPECT_EQ(r.reason, NoReadingReason::TooFewValidPixels);
    EXPECT_TRUE(r.calibration_suspect);
    // A pair that was not processed compared no rows.
    facts.pair = PairOutcome::BadFrame;
    EXPECT_FALSE(judgeReading(facts).calibration_suspect);
}

TEST(ReadingVerdict, ReasonsThatNeedNumbersCarryThem)
{
    ReadingFacts facts = goodPair();
    facts.skew_ms = 12.5;
    Reading r = judgeReading(facts);
    EXPECT_EQ(r.reason, NoReadingReason::OutOfSync);
    EXPECT_DOUBLE_EQ(r.skew_ms, 12.5);
    EXPECT_DOUBLE_EQ(r.max_skew_ms, 10.0);
    facts = goodPair();
    facts.age_ms = 800.0;
    r = judgeReading(facts);
    EXPECT_EQ(r.reason, NoReadingReason::Stale);
    EXPECT_DOUBLE_EQ(r.age_ms, 800.0);
    EXPECT_DOUBLE_EQ(r.max_age_ms, 500.0);
}

TEST(ReadingVerdict, OpenCvMatchersSayTheGuardIsOff)
{
    ReadingFacts facts = goodPair();
    facts.near_field.guard_active = false;
    const Reading r = judgeReading(facts);
    EXPECT_TRUE(r.valid);
    EXPECT_FALSE(r.near_field_guard);
}

} // namespace
} // namespace stereod
