// How stereoctl reads the protocol's reading object: exit codes per reason class, and
// the printed lines.

#include <gtest/gtest.h>

#include "ctl/exit_codes.hpp"
#include "ctl/reading_format.hpp"

namespace stereod {
namespace {

using Json = nlohmann::ordered_json;

Json noReading(const char* code, const char* message)
{
    return {{"valid", false},
            {"distance_m", nullptr},
            {"stamp_ns", 81263511234},
            {"age_ms", 37.2},
            {"frame", 118},
            {"valid_fraction", 0.02},
            {"in_range_fraction", 0.0},
            {"region_pixels", 355680},
            {"reason", {{"code", code}, {"message", message}}}};
}

TEST(ReadingFormat, EveryReasonCodeOfTheProtocolIsKnown)
{
    for (const char* code : {"too_few_valid_pixels", "nothing_in_range", "bad_frame", "out_of_sync",
                             "source_down", "stale", "no_frame_yet"}) {
        const auto reason = reasonFromCode(code);
        ASSERT_TRUE(reason.has_value()) << code;
        EXPECT_STREQ(reasonCode(*reason), code);
    }
    EXPECT_FALSE(reasonFromCode("cosmic_rays").has_value());
}

TEST(ReadingFormat, ExitCodeFollowsTheReasonClass)
{
    const Json valid = {{"valid", true}, {"distance_m", 0.873}, {"frame", 3}};
    EXPECT_EQ(exitCodeForReading(valid), kExitOk);
    for (const char* code : {"too_few_valid_pixels", "nothing_in_range", "bad_frame"}) {
        EXPECT_EQ(exitCodeForReading(noReading(code, "x")), kExitNoReading) << code;
    }
    for (const char* code : {"out_of_sync", "source_down", "stale", "no_frame_yet"}) {
        EXPECT_EQ(exitCodeForReading(noReading(code, "x")), kExitNotProducing) << code;
    }
}

// A region the image's left edge cuts short of the distance: the number stands (exit 0),
// and the line says how much of the region could hide something nearer.
TEST(ReadingFormat, ARegionShortOfTheDistanceAtTheLeftEdgeIsPrinted)
{
    Json reading = {{"valid", true},  {"distance_m", 0.264},    {"frame", 3},
                    {"age_ms", 12.0}, {"valid_fraction", 0.68}, {"out_of_view_fraction", 0.1094}};
    EXPECT_EQ(exitCodeForReading(reading), kExitOk);
    EXPECT_EQ(formatDistance(reading),
              "0.264 m  LEFT EDGE: 11 % of the region cannot see this near");
    EXPECT_EQ(formatWatchLine(reading), "frame 3  0.264 m  age 12 ms  valid 68 %  LEFT EDGE: 11 % "
                                        "of the region cannot see this near");
    reading["calibration_suspect"] = true;
    EXPECT_EQ(formatDistance(reading),
              "0.264 m  CALIBRATION SUSPECT  LEFT EDGE: 11 % of the region cannot see this near");
}

TEST(ReadingFormat, ASuspectCalibrationHasItsOwnExitCodeAndIsPrinted)
{
    Json suspect = {{"valid", true},
                    {"distance_m", 0.278},
                    {"frame", 3},
                    {"age_ms", 12.0},
                    {"valid_fraction", 0.5},
                    {"calibration_suspect", true},
                    {"calibration_row_offset_px", 1.523}};
    EXPECT_TRUE(calibrationSuspect(suspect));
    EXPECT_EQ(exitCodeForReading(suspect), kExitCalibrationSuspect);
    EXPECT_EQ(kExitCalibrationSuspect, 4);
    EXPECT_EQ(formatDistance(suspect), "0.278 m  CALIBRATION SUSPECT: rows +1.52 px apart");
    EXPECT_EQ(formatWatchLine(suspect),
              "frame 3  0.278 m  age 12 ms  valid 50 %  CALIBRATION SUSPECT: rows +1.52 px apart");
    suspect.erase("calibration_row_offset_px");
    EXPECT_EQ(formatDistance(suspect), "0.278 m  CALIBRATION SUSPECT");
    // A reading withheld for the calibration keeps the exit code of "no reading".
    Json withheld = noReading("calibration_suspect", "calibration suspect: rows +2.40 px apart");
    withheld["calibration_suspect"] = true;
    EXPECT_EQ(exitCodeForReading(withheld), kExitNoReading);
    EXPECT_EQ(formatDistance(withheld), "no reading: calibration suspect: rows +2.40 px apart");
    // Not flagged, or flagged false: a plain reading.
    suspect["calibration_suspect"] = false;
    EXPECT_FALSE(calibrationSuspect(suspect));
    EXPECT_EQ(exitCodeForReading(suspect), kExitOk);
}

TEST(ReadingFormat, AReadingThatDoesNotAddUpIsNeverValid)
{
    // valid:true without a number, or a reason nobody knows: not a distance to act on.
    EXPECT_EQ(exitCodeForReading({{"valid", true}, {"distance_m", nullptr}}), kExitNotProducing);
    EXPECT_EQ(exitCodeForReading(noReading("cosmic_rays", "?")), kExitNotProducing);
    EXPECT_EQ(exitCodeForReading(Json::object()), kExitNotProducing);
    EXPECT_EQ(formatDistance({{"valid", true}, {"distance_m", "1.2"}}),
              "no reading: the service gave no reason");
}

TEST(ReadingFormat, DistanceLine)
{
    EXPECT_EQ(formatDistance({{"valid", true}, {"distance_m", 0.87349}}), "0.873 m");
    EXPECT_EQ(formatDistance(noReading("too_few_valid_pixels",
                                       "too few valid pixels in the region: 2.0 % valid, "
                                       "10.0 % needed")),
              "no reading: too few valid pixels in the region: 2.0 % valid, 10.0 % needed");
    Json code_only = noReading("stale", "");
    code_only["reason"].erase("message");
    EXPECT_EQ(formatDistance(code_only), "no reading: stale");
}

TEST(ReadingFormat, WatchLine)
{
    const Json valid = {{"valid", true},  {"distance_m", 1.412}, {"stamp_ns", 5},
                        {"age_ms", 37.2}, {"frame", 118},        {"valid_fraction", 0.83}};
    EXPECT_EQ(formatWatchLine(valid), "frame 118  1.412 m  age 37 ms  valid 83 %");
    EXPECT_EQ(formatWatchLine(noReading("source_down", "frame source down")),
              "frame 118  no reading: frame source down  age 37 ms  valid 2 %");
}

} // namespace
} // namespace stereod
