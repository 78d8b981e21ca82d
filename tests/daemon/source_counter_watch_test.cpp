// The journal's view of bad, dropped and unpaired frames: one line per camera whose
// counts grew, saying how many in how long, never more often than the interval, nothing
// left out between two lines.

#include <gtest/gtest.h>

#include "daemon/source_counter_watch.hpp"

namespace stereod {
namespace {

constexpr int64_t kSecondNs = 1'000'000'000;

SourceStatus twoCameras(uint64_t left_bad, uint64_t right_bad, uint64_t right_dropped = 0,
                        uint64_t right_unpaired = 0)
{
    SourceStatus status;
    CameraStatus left;
    left.name = "left";
    left.bad_frames = left_bad;
    CameraStatus right;
    right.name = "right";
    right.bad_frames = right_bad;
    right.dropped = right_dropped;
    right.unpaired = right_unpaired;
    if (right_bad > 0)
        right.last_bad_frame = "not a JPEG (no SOI marker)";
    status.cameras = {left, right};
    return status;
}

TEST(SourceCounterWatch, SaysNothingWhileNoCountGrows)
{
    SourceCounterWatch watch(5 * kSecondNs);
    EXPECT_TRUE(watch.due(0));
    EXPECT_TRUE(watch.look(twoCameras(0, 0), 0).empty());
    EXPECT_FALSE(watch.due(4 * kSecondNs));
    EXPECT_TRUE(watch.due(5 * kSecondNs));
    EXPECT_TRUE(watch.look(twoCameras(0, 0), 5 * kSecondNs).empty());
}

TEST(SourceCounterWatch, OneLinePerCameraWithCountsReasonAndTime)
{
    SourceCounterWatch watch(5 * kSecondNs);
    watch.look(twoCameras(0, 0), 0);
    const auto reports = watch.look(twoCameras(0, 75, 3, 1), 5 * kSecondNs);
    ASSERT_EQ(reports.size(), 1u);
    EXPECT_EQ(reports[0].text, "camera right: 75 bad frames (latest: not a JPEG (no SOI marker)), "
                               "3 frames dropped, 1 frame unpaired in the last 5.0 s");
    EXPECT_TRUE(reports[0].bad_frames);
}

TEST(SourceCounterWatch, CountsFromTheLastLookSoNothingIsLeftOut)
{
    SourceCounterWatch watch(5 * kSecondNs);
    watch.look(twoCameras(0, 0), 0);
    watch.look(twoCameras(2, 10), 5 * kSecondNs);
    const auto reports = watch.look(twoCameras(2, 25), 11 * kSecondNs);
    ASSERT_EQ(reports.size(), 1u) << reports[0].text;
    EXPECT_EQ(reports[0].text.rfind("camera right: 15 bad frames", 0), 0u) << reports[0].text;
    EXPECT_NE(reports[0].text.find("in the last 6.0 s"), std::string::npos) << reports[0].text;
}

TEST(SourceCounterWatch, FirstLookReportsWhatHappenedSinceTheStart)
{
    SourceCounterWatch watch;
    const auto reports = watch.look(twoCameras(1, 0), 7 * kSecondNs);
    ASSERT_EQ(reports.size(), 1u);
    EXPECT_EQ(reports[0].text, "camera left: 1 bad frame since the start");
}

TEST(SourceCounterWatch, DroppedAndUnpairedAloneAreInformationNotWarning)
{
    SourceCounterWatch watch;
    watch.look(twoCameras(0, 0), 0);
    const auto reports = watch.look(twoCameras(0, 0, 4, 0), 5 * kSecondNs);
    ASSERT_EQ(reports.size(), 1u);
    EXPECT_FALSE(reports[0].bad_frames);
    EXPECT_EQ(reports[0].text, "camera right: 4 frames dropped in the last 5.0 s");
}

TEST(SourceCounterWatch, ACounterThatWentBackCountsFromZero)
{
    // A source replaced (camera list rebuilt) starts its counters again.
    SourceCounterWatch watch;
    watch.look(twoCameras(0, 50), 0);
    const auto reports = watch.look(twoCameras(0, 3), 5 * kSecondNs);
    ASSERT_EQ(reports.size(), 1u);
    EXPECT_EQ(reports[0].text.rfind("camera right: 3 bad frames", 0), 0u) << reports[0].text;
}

} // namespace
} // namespace stereod
