// The reading object (docs/protocol.md, "The reading object"): valid, refused with its
// reason and numbers, without a frame, and never a number when not valid.

#include <cmath>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "protocol/reading_json.hpp"
#include "tests/protocol/sample_reading.hpp"

namespace stereod {
namespace {

TEST(ProtocolReading, ValidReadingHasEveryField)
{
    ReadingReport report;
    report.reading = sampleValidReading();
    const int64_t now_ns = report.reading.stamp_ns + 37'200'000;
    const Json reading = readingToJson(report, now_ns);
    EXPECT_EQ(reading["valid"], true);
    EXPECT_NEAR(reading["distance_m"].get<double>(), 1.4125, 1e-9);
    EXPECT_EQ(reading["stamp_ns"], 81263511234);
    EXPECT_NEAR(reading["age_ms"].get<double>(), 37.2, 1e-9);
    EXPECT_EQ(reading["frame"], 118);
    EXPECT_NEAR(reading["valid_fraction"].get<double>(), 0.83, 1e-12);
    EXPECT_NEAR(reading["in_range_fraction"].get<double>(), 0.8, 1e-12);
    EXPECT_EQ(reading["region_pixels"], 355680);
    EXPECT_FALSE(reading.contains("reason"));
}

// The share of the region that cannot see as near as the distance: said when there is one.
TEST(ProtocolReading, ARegionShortOfTheDistanceSaysHowMuch)
{
    ReadingReport report;
    report.reading = sampleValidReading();
    const int64_t now_ns = report.reading.stamp_ns;
    EXPECT_FALSE(readingToJson(report, now_ns).contains("out_of_view_fraction"));
    report.reading.out_of_view_fraction = 0.10937;
    const Json reading = readingToJson(report, now_ns);
    EXPECT_NEAR(reading["out_of_view_fraction"].get<double>(), 0.1094, 1e-12);
    EXPECT_EQ(reading["valid"], true); // a caveat on the number, not a refusal
}

TEST(ProtocolReading, RefusalCarriesReasonWithNumbers)
{
    ReadingReport report;
    report.reading = sampleValidReading();
    report.reading.valid = false;
    report.reading.reason = NoReadingReason::TooFewValidPixels;
    report.reading.valid_fraction = 0.02;
    report.reading.in_range_fraction = 0.0;
    const Json reading = readingToJson(report, report.reading.stamp_ns);
    EXPECT_EQ(reading["valid"], false);
    EXPECT_TRUE(reading["distance_m"].is_null());
    EXPECT_EQ(reading["reason"]["code"], "too_few_valid_pixels");
    EXPECT_EQ(reading["reason"]["message"],
              "too few valid pixels in the region: 2.0 % valid, 10.0 % needed");

    report.reading.reason = NoReadingReason::NothingInRange;
    report.reading.valid_fraction = 0.83;
    report.reading.in_range_fraction = 0.0001;
    report.reading.region_pixels = 200000;
    report.reading.min_pixels = 50;
    EXPECT_EQ(readingToJson(report, 0)["reason"]["message"],
              "nothing within the depth range in the region: 20 pixels in range, 50 needed "
              "(83.0 % valid, 0.0 % in range)");
}

TEST(ProtocolReading, DetailFollowsTheReasonAndIsEscaped)
{
    ReadingReport report;
    report.reading = sampleValidReading();
    report.reading.valid = false;
    report.reading.reason = NoReadingReason::BadFrame;
    const std::string message = "cannot decode \"left.png\":\n\tbad\x01 byte \xc3 here";
    report.detail = message;
    std::string text;
    appendReadingJson(text, report, report.reading.stamp_ns);
    const Json reading = Json::parse(text);
    EXPECT_EQ(reading["reason"]["code"], "bad_frame");
    const std::string got = reading["reason"]["message"];
    const std::string prefix = "the frame pair could not be processed: ";
    EXPECT_EQ(got.substr(0, prefix.size() + 28), prefix + "cannot decode \"left.png\":\n\tb");
    EXPECT_NE(got.find("\x01"), std::string::npos);
    EXPECT_NE(got.find("\xEF\xBF\xBD"), std::string::npos); // the lone 0xC3 replaced
}

TEST(ProtocolReading, NoFrameYetHasNoStampNorAge)
{
    ReadingReport report;
    report.reading.reason = NoReadingReason::NoFrameYet;
    report.has_frame = false;
    const Json reading = readingToJson(report, 123);
    EXPECT_EQ(reading["valid"], false);
    EXPECT_FALSE(reading.contains("stamp_ns"));
    EXPECT_FALSE(reading.contains("age_ms"));
    EXPECT_EQ(reading["reason"]["code"], "no_frame_yet");

    // A source that failed before its first pair: source_down, still without a stamp.
    report.reading.reason = NoReadingReason::SourceDown;
    report.detail = "the replay source is failed";
    const Json down = readingToJson(report, 123);
    EXPECT_FALSE(down.contains("stamp_ns"));
    EXPECT_EQ(down["reason"]["code"], "source_down");
    EXPECT_EQ(down["reason"]["message"], "frame source down: the replay source is failed");
}

TEST(ProtocolReading, InconsistentValidFlagIsNeverANumber)
{
    ReadingReport report;
    report.reading = sampleValidReading();
    report.reading.reason = NoReadingReason::NothingInRange; // valid stays true
    const Json reading = readingToJson(report, report.reading.stamp_ns);
    EXPECT_EQ(reading["valid"], false);
    EXPECT_TRUE(reading["distance_m"].is_null());
}

} // namespace
} // namespace stereod
