// The replay source on recordings made at test time: order, stamps, loops, pacing, bad
// files, failure to start, and stopping (CI runs these under ThreadSanitizer).

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <dirent.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include "replay/mcap_recording.hpp"
#include "replay/recording.hpp"
#include "replay/replay_source.hpp"
#include "tests/support/bags.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/descriptor_exhaustion.hpp"
#include "tests/support/process.hpp"
#include "tests/support/recordings.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

namespace fs = std::filesystem;
using test::TempDir; // tests/ctl/process.hpp
using test::TestPair;

constexpr int64_t kMs = 1'000'000;

ReplayOptions lockstep(const std::string& path, bool loop = false)
{
    ReplayOptions options;
    options.path = path;
    options.pacing = ReplayPacing::Lockstep;
    options.loop = loop;
    // Tests keep every pair they pop; the pool must cover that (a worker keeps one).
    options.pool_pairs = 16;
    return options;
}

ReplayOptions paced(const std::string& path, bool loop, std::size_t pool_pairs)
{
    ReplayOptions options;
    options.path = path;
    options.pacing = ReplayPacing::Paced;
    options.loop = loop;
    options.pool_pairs = pool_pairs;
    return options;
}

// Waits (politely) until the source reaches `state`; false after a generous limit, which
// only a hung source reaches.
bool waitForState(const ReplaySource& source, SourceState state)
{
    for (int i = 0; i < 20'000; ++i) {
        if (source.status().state == state)
            return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return false;
}

std::vector<StereoPair> popPairs(PairRing& ring, std::size_t count)
{
    std::vector<StereoPair> pairs;
    for (std::size_t k = 0; k < count; ++k) {
        std::optional<StereoPair> pair = ring.pop();
        if (!pair)
            break;
        pairs.push_back(std::move(*pair));
    }
    return pairs;
}

bool haveOpenCvSamples()
{
    return fs::exists(test::opencvSamplesDir() + "/left01.jpg");
}

// Checks one delivered pair against the recorded pair it came from.
void expectPairMatches(const StereoPair& pair, const TestPair& recorded, uint64_t index)
{
    ASSERT_TRUE(pair.left);
    ASSERT_TRUE(pair.right);
    EXPECT_EQ(pair.index, index);
    EXPECT_EQ(pair.left->sequence, index);
    EXPECT_EQ(pair.right->sequence, index);
    EXPECT_EQ(pair.left->source_stamp_ns, recorded.left_stamp_ns);
    EXPECT_EQ(pair.right->source_stamp_ns, recorded.right_stamp_ns);
    EXPECT_EQ(pair.skewNs(), recorded.right_stamp_ns - recorded.left_stamp_ns);
    EXPECT_TRUE(test::samePixels(pair.left->image, recorded.left)) << "left of pair " << index;
    EXPECT_TRUE(test::samePixels(pair.right->image, recorded.right)) << "right of pair " << index;
}

// A source and its ring, torn down in the safe order whatever a test does: stop the
// source, drain the ring, then free the source (and with it the frames' pool).
struct Rig {
    Rig(ReplayOptions options, std::size_t ring_capacity)
        : source(std::move(options)), ring(ring_capacity)
    {
    }
    ~Rig()
    {
        source.stop();
        while (ring.tryPop()) {
        }
    }
    ReplaySource source;
    PairRing ring;
};

class ReplaySourceTest : public ::testing::Test {
  protected:
    // A recording of `count` Tsukuba pairs, 40 ms apart, with the test skews.
    std::string makeRecording(int count, int64_t spacing_ns = 40 * kMs)
    {
        pairs_ = test::tsukubaPairs(count);
        test::stampPairs(pairs_, 7'000'000'000, spacing_ns);
        const std::string dir = tmp_.file("rec");
        test::writeRecording(dir, pairs_);
        return dir;
    }

    TempDir tmp_;
    std::vector<TestPair> pairs_;
};

TEST_F(ReplaySourceTest, LockstepDeliversEveryPairInOrderThenFinishes)
{
    const std::string dir = makeRecording(6);
    Rig rig(lockstep(dir), 2); // smaller than the recording: the source must wait, not drop
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    EXPECT_EQ(source.frameSize(), cv::Size(96, 72));
    EXPECT_EQ(source.pairCount(), 6u);
    EXPECT_TRUE(source.calibrationPath().empty());

    const int64_t started_ns = monotonicNowNs();
    ASSERT_EQ(source.start(ring), 0);
    std::vector<StereoPair> got = popPairs(ring, 6);
    ASSERT_EQ(got.size(), 6u);
    int64_t previous_ns = started_ns;
    for (std::size_t k = 0; k < got.size(); ++k) {
        expectPairMatches(got[k], pairs_[k], k);
        EXPECT_GE(got[k].stampNs(), previous_ns); // delivery times, CLOCK_MONOTONIC
        previous_ns = got[k].stampNs();
    }
    EXPECT_LE(previous_ns, monotonicNowNs());

    ASSERT_TRUE(waitForState(source, SourceState::Finished));
    EXPECT_FALSE(ring.tryPop().has_value());
    EXPECT_EQ(ring.dropped(), 0u);
    const SourceStatus status = source.status();
    EXPECT_EQ(status.kind, "replay");
    EXPECT_EQ(status.pairs, 6u);
    EXPECT_TRUE(status.last_error.empty());
    ASSERT_EQ(status.cameras.size(), 2u);
    EXPECT_EQ(status.cameras[0].name, "left");
    EXPECT_EQ(status.cameras[1].name, "right");
    for (const CameraStatus& camera : status.cameras) {
        EXPECT_EQ(camera.state, SourceState::Finished);
        EXPECT_EQ(camera.frames, 6u);
        EXPECT_EQ(camera.bad_frames, 0u);
        EXPECT_EQ(camera.dropped, 0u);
    }
    // |skew| of the six recorded pairs: 150, 300, 450, 150, 300, 450 us.
    EXPECT_NEAR(status.skew_mean_ms, 0.3, 1e-9);
    EXPECT_NEAR(status.skew_max_ms, 0.45, 1e-9);
    EXPECT_NEAR(status.skew_p99_ms, 0.45, 1e-9);

    got.clear();
    source.stop();
    EXPECT_EQ(source.status().state, SourceState::Finished);
}

TEST_F(ReplaySourceTest, LockstepWaitsForBuffersHeldDownstreamInsteadOfDropping)
{
    const std::string dir = makeRecording(8);
    ReplayOptions options = lockstep(dir);
    options.pool_pairs = 2; // fewer than the ring holds plus what the consumer keeps
    Rig rig(options, 4);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    ASSERT_EQ(source.start(ring), 0);

    // The consumer keeps the pair it took last, as a worker keeps its current pair.
    std::vector<StereoPair> held;
    for (uint64_t k = 0; k < 8; ++k) {
        std::optional<StereoPair> pair = ring.pop();
        ASSERT_TRUE(pair.has_value());
        expectPairMatches(*pair, pairs_[k], k);
        held.push_back(std::move(*pair));
        if (held.size() > 1)
            held.erase(held.begin());
    }
    ASSERT_TRUE(waitForState(source, SourceState::Finished));
    EXPECT_EQ(source.status().cameras[0].dropped, 0u);
    EXPECT_EQ(ring.dropped(), 0u);
}

TEST_F(ReplaySourceTest, LoopWrapsAroundWithIncreasingIndices)
{
    const std::string dir = makeRecording(3);
    Rig rig(lockstep(dir, /*loop=*/true), 2);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    ASSERT_EQ(source.start(ring), 0);
    std::vector<StereoPair> got = popPairs(ring, 8);
    ASSERT_EQ(got.size(), 8u);
    for (std::size_t k = 0; k < got.size(); ++k) {
        expectPairMatches(got[k], pairs_[k % 3], k);
        if (k > 0) {
            EXPECT_GE(got[k].stampNs(), got[k - 1].stampNs());
            EXPECT_GT(got[k].left->sequence, got[k - 1].left->sequence);
        }
    }
    EXPECT_EQ(source.status().state, SourceState::Running);
    EXPECT_EQ(source.start(ring), -EBUSY);
    got.clear();
    source.stop();
    EXPECT_EQ(source.status().state, SourceState::Stopped);

    // Started again, it replays from the first pair and the numbering goes on.
    while (ring.tryPop()) {
    }
    ring.restart();
    ASSERT_EQ(source.start(ring), 0);
    std::optional<StereoPair> next = ring.pop();
    ASSERT_TRUE(next.has_value());
    EXPECT_GT(next->index, 7u);
    EXPECT_EQ(next->index % 3, 0u);
    EXPECT_EQ(next->left->source_stamp_ns, pairs_[0].left_stamp_ns);
}

TEST_F(ReplaySourceTest, PacedDeliveryKeepsTheRecordedSpacing)
{
    const int64_t spacing_ns = 30 * kMs;
    const std::string dir = makeRecording(5, spacing_ns);
    ReplayOptions options;
    options.path = dir;
    options.pacing = ReplayPacing::Paced;
    options.loop = false;
    options.pool_pairs = 10;
    Rig rig(options, 8);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;

    const int64_t started_ns = monotonicNowNs();
    ASSERT_EQ(source.start(ring), 0);
    std::vector<StereoPair> got = popPairs(ring, 5);
    ASSERT_EQ(got.size(), 5u);
    for (std::size_t k = 0; k < got.size(); ++k) {
        expectPairMatches(got[k], pairs_[k], k);
        // Never earlier than its recorded offset from the start (no upper bound: a busy
        // machine may deliver late).
        const int64_t recorded_offset_ns = pairs_[k].left_stamp_ns - pairs_[0].left_stamp_ns;
        EXPECT_GE(got[k].stampNs() - started_ns, recorded_offset_ns) << "pair " << k;
        if (k > 0) {
            EXPECT_GT(got[k].stampNs(), got[k - 1].stampNs());
        }
    }
    ASSERT_TRUE(waitForState(source, SourceState::Finished));
    EXPECT_EQ(ring.dropped(), 0u);
}

TEST_F(ReplaySourceTest, StampsSteppingBackKeepThePaceAndAreWarnedOnce)
{
    // Spliced from two runs: pairs 3..5 were stamped 6 s before pairs 0..2.
    const int64_t spacing_ns = 40 * kMs;
    pairs_ = test::tsukubaPairs(6);
    test::stampPairs(pairs_, 7'000'000'000, spacing_ns);
    for (std::size_t k = 3; k < pairs_.size(); ++k) {
        pairs_[k].left_stamp_ns -= 6'000'000'000;
        pairs_[k].right_stamp_ns -= 6'000'000'000;
    }
    const std::string dir = tmp_.file("spliced");
    test::writeRecording(dir, pairs_);

    auto sink = std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(64);
    auto previous = spdlog::default_logger();
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("replay-test", sink));
    ReplayOptions options;
    options.path = dir;
    options.pacing = ReplayPacing::Paced;
    options.loop = true;
    options.pool_pairs = 24; // the test keeps every pair it pops
    std::size_t got_count = 0;
    double elapsed_s = 0.0;
    {
        Rig rig(options, 16);
        const auto started = std::chrono::steady_clock::now();
        EXPECT_EQ(rig.source.start(rig.ring), 0);
        // Three passes: 18 pairs, 40 ms apart, about 0.7 s.
        got_count = popPairs(rig.ring, 18).size();
        elapsed_s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
        rig.source.stop();
    }
    spdlog::set_default_logger(previous);
    EXPECT_EQ(got_count, 18u);
    EXPECT_LT(elapsed_s, 2.0) << "the replay stalled at the step back";
    std::size_t warnings = 0;
    for (const std::string& line : sink->last_formatted())
        warnings += line.find("step back") != std::string::npos ? 1 : 0;
    EXPECT_EQ(warnings, 1u);
}

TEST_F(ReplaySourceTest, ExtremeStampsGiveASaturatedSkewNotAWrappedOne)
{
    pairs_ = test::tsukubaPairs(3);
    test::stampPairs(pairs_, 7'000'000'000, 40 * kMs);
    // Right minus left overflows: wrapped, it would read -1 ns, "in sync".
    pairs_[1].left_stamp_ns = std::numeric_limits<int64_t>::min();
    pairs_[1].right_stamp_ns = std::numeric_limits<int64_t>::max();
    pairs_[2].left_stamp_ns = std::numeric_limits<int64_t>::max();
    pairs_[2].right_stamp_ns = std::numeric_limits<int64_t>::min();
    const std::string dir = tmp_.file("extreme");
    test::writeRecording(dir, pairs_);

    Rig rig(lockstep(dir), 4);
    ASSERT_EQ(rig.source.start(rig.ring), 0) << rig.source.status().last_error;
    const std::vector<StereoPair> got = popPairs(rig.ring, 3);
    ASSERT_EQ(got.size(), 3u);
    // Delivered stamps are "now" plus the recorded skew, saturated: as far apart as they go.
    EXPECT_GT(got[1].skewNs(), std::numeric_limits<int64_t>::max() / 2);
    EXPECT_LT(got[2].skewNs(), std::numeric_limits<int64_t>::min() / 2);
    EXPECT_EQ(got[1].right->source_stamp_ns, std::numeric_limits<int64_t>::max());
    const SourceStatus status = rig.source.status();
    EXPECT_GT(status.skew_max_ms, 1e12) << "the largest skew wrapped";
    EXPECT_GT(status.skew_mean_ms, 1e12) << "the mean skew wrapped";
}

TEST_F(ReplaySourceTest, PacedReplayDropsPairsWhenEveryBufferIsHeld)
{
    const std::string dir = makeRecording(4, 1 * kMs);
    ReplayOptions options;
    options.path = dir;
    options.pacing = ReplayPacing::Paced;
    options.loop = false;
    options.pool_pairs = 1; // the first pair, unconsumed in the ring, holds both buffers
    Rig rig(options, 4);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    ASSERT_EQ(source.start(ring), 0);
    ASSERT_TRUE(waitForState(source, SourceState::Finished));

    const SourceStatus status = source.status();
    EXPECT_EQ(status.pairs, 1u);
    EXPECT_EQ(status.cameras[0].dropped, 3u);
    std::optional<StereoPair> only = ring.tryPop();
    ASSERT_TRUE(only.has_value());
    expectPairMatches(*only, pairs_[0], 0);
    EXPECT_FALSE(ring.tryPop().has_value());
}

TEST_F(ReplaySourceTest, StopDuringALongPacedGapReturnsAtOnce)
{
    // Two pairs an hour apart: stop() must cut the wait short, not sit it out.
    pairs_ = test::tsukubaPairs(2);
    test::stampPairs(pairs_, 0, int64_t{3600} * 1'000'000'000);
    test::writeRecording(tmp_.file("rec"), pairs_);
    ReplayOptions options;
    options.path = tmp_.file("rec");
    options.pacing = ReplayPacing::Paced;
    Rig rig(options, 2);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    ASSERT_EQ(source.start(ring), 0);
    std::optional<StereoPair> first = ring.pop();
    ASSERT_TRUE(first.has_value());
    expectPairMatches(*first, pairs_[0], 0);

    source.stop();
    EXPECT_EQ(source.status().state, SourceState::Stopped);
    EXPECT_EQ(source.status().pairs, 1u);
    EXPECT_FALSE(ring.tryPop().has_value());
    EXPECT_FALSE(ring.stopped()); // paced: the ring is left as it was
}

TEST_F(ReplaySourceTest, StopReleasesALockstepReplayWaitingOnAFullRing)
{
    const std::string dir = makeRecording(3);
    Rig rig(lockstep(dir, /*loop=*/true), 2);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    ASSERT_EQ(source.start(ring), 0);
    // Nobody consumes: the ring fills and the source blocks in pushWait().
    for (int i = 0; i < 20'000 && ring.size() < 2; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    ASSERT_EQ(ring.size(), 2u);

    source.stop();
    EXPECT_EQ(source.status().state, SourceState::Stopped);
    EXPECT_TRUE(ring.stopped());
    EXPECT_EQ(ring.dropped(), 0u);
    std::vector<StereoPair> left_over = popPairs(ring, 4);
    EXPECT_EQ(left_over.size(), 2u);
}

TEST_F(ReplaySourceTest, PlainFolderReplaysAtTheNominalRate)
{
    pairs_ = test::tsukubaPairs(5);
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const std::string n = "_" + std::to_string(k) + ".png";
        ASSERT_TRUE(cv::imwrite(tmp_.file("left" + n), pairs_[k].left));
        ASSERT_TRUE(cv::imwrite(tmp_.file("right" + n), pairs_[k].right));
        pairs_[k].left_stamp_ns = static_cast<int64_t>(k) * 40 * kMs; // 25 fps
        pairs_[k].right_stamp_ns = pairs_[k].left_stamp_ns;
    }
    ReplayOptions options = lockstep(tmp_.path());
    options.fps = 25.0;
    Rig rig(options, 2);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    ASSERT_EQ(source.start(ring), 0);
    std::vector<StereoPair> got = popPairs(ring, 5);
    ASSERT_EQ(got.size(), 5u);
    for (std::size_t k = 0; k < got.size(); ++k)
        expectPairMatches(got[k], pairs_[k], k);
    ASSERT_TRUE(waitForState(source, SourceState::Finished));
}

TEST_F(ReplaySourceTest, ChessboardSamplePairsReplayFromAFolderOfLinks)
{
    const std::string samples = test::opencvSamplesDir();
    if (!haveOpenCvSamples())
        GTEST_SKIP() << "opencv-doc sample data not installed in " << samples;
    // Links, not copies, to the 13 real 640x480 pairs.
    std::vector<std::string> names;
    for (int n = 1; n <= 14; ++n) {
        if (n == 10)
            continue;
        const std::string number = (n < 10 ? "0" : "") + std::to_string(n) + ".jpg";
        for (const char* side : {"left", "right"})
            fs::create_symlink(samples + "/" + side + number, tmp_.file(side + number));
        names.push_back(number);
    }
    Rig rig(lockstep(tmp_.path()), 4);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    EXPECT_EQ(source.frameSize(), cv::Size(640, 480));
    ASSERT_EQ(source.start(ring), 0);
    std::vector<StereoPair> got = popPairs(ring, names.size());
    ASSERT_EQ(got.size(), names.size());
    for (std::size_t k = 0; k < got.size(); ++k) {
        EXPECT_EQ(got[k].index, k);
        const cv::Mat left = cv::imread(samples + "/left" + names[k], cv::IMREAD_GRAYSCALE);
        EXPECT_TRUE(test::samePixels(got[k].left->image, left)) << "left" << names[k];
    }
    ASSERT_TRUE(waitForState(source, SourceState::Finished));
    EXPECT_EQ(source.status().cameras[0].bad_frames, 0u);
}

TEST_F(ReplaySourceTest, OpenCvSampleFolderSkipsPairsOfAnotherSize)
{
    // The sample folder as it is: left.jpg/right.jpg (612x459) come first by name and fix
    // the frame size, so the 13 chessboard pairs (640x480) are skipped as bad frames.
    const std::string samples = test::opencvSamplesDir();
    if (!haveOpenCvSamples())
        GTEST_SKIP() << "opencv-doc sample data not installed in " << samples;
    Rig rig(lockstep(samples), 4);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    EXPECT_EQ(source.frameSize(), cv::Size(612, 459));
    ASSERT_EQ(source.start(ring), 0);
    ASSERT_TRUE(waitForState(source, SourceState::Finished));
    const SourceStatus status = source.status();
    EXPECT_EQ(status.pairs, 1u);
    EXPECT_EQ(status.cameras[0].bad_frames, 13u);
    EXPECT_NE(status.cameras[0].last_error.find("640x480"), std::string::npos)
        << status.cameras[0].last_error;
    EXPECT_EQ(popPairs(ring, 1).size(), 1u);
    source.stop();
}

TEST_F(ReplaySourceTest, BadFilesAreSkippedCountedAndLoggedOncePerFile)
{
    const std::string dir = makeRecording(7);
    test::writeGarbage(dir + "/left/000002.png"); // corrupt
    fs::remove(dir + "/right/000004.png");        // missing
    const std::vector<TestPair> big = test::tsukubaPairs(1, cv::Size(120, 90));
    cv::imwrite(dir + "/left/000005.png", big[0].left); // another size
    cv::imwrite(dir + "/right/000005.png", big[0].right);

    // Capture the warnings.
    auto sink = std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(256);
    auto previous = spdlog::default_logger();
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("replay-test", sink));

    Rig rig(lockstep(dir, /*loop=*/true), 2);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    ASSERT_EQ(source.start(ring), 0);
    // Two whole passes (4 good pairs each) and the first pair of the third.
    const uint64_t good[] = {0, 1, 3, 6};
    std::vector<StereoPair> got = popPairs(ring, 9);
    ASSERT_EQ(got.size(), 9u);
    for (std::size_t k = 0; k < got.size(); ++k) {
        const uint64_t position = good[k % 4];
        expectPairMatches(got[k], pairs_[position], (k / 4) * 7 + position);
    }
    got.clear();
    source.stop();
    spdlog::set_default_logger(previous);

    const SourceStatus status = source.status();
    // Two whole passes saw every bad file once each; the third, running ahead of the
    // consumer into the ring, may have met them once more before stop().
    EXPECT_GE(status.cameras[0].bad_frames, 4u); // 000002 corrupt, 000005 wrong size
    EXPECT_LE(status.cameras[0].bad_frames, 6u);
    EXPECT_GE(status.cameras[1].bad_frames, 2u); // 000004 missing
    EXPECT_LE(status.cameras[1].bad_frames, 3u);
    EXPECT_EQ(status.cameras[0].dropped, 0u);
    EXPECT_FALSE(status.cameras[1].last_error.empty());

    int corrupt = 0;
    int missing = 0;
    int resized = 0;
    for (const std::string& line : sink->last_formatted()) {
        corrupt += line.find("left/000002.png") != std::string::npos ? 1 : 0;
        missing += line.find("right/000004.png") != std::string::npos ? 1 : 0;
        resized += line.find("left/000005.png") != std::string::npos ? 1 : 0;
    }
    EXPECT_EQ(corrupt, 1);
    EXPECT_EQ(missing, 1);
    EXPECT_EQ(resized, 1);
}

// The process's peak resident memory so far, in MB.
double peakRssMb()
{
    rusage usage{};
    ::getrusage(RUSAGE_SELF, &usage);
    return static_cast<double>(usage.ru_maxrss) / 1024.0; // ru_maxrss is in KB
}

// Runs a looping lockstep replay of `dir` for two passes of `count` pairs with the log
// captured; returns the log lines.
std::vector<std::string> replayTwoPasses(const std::string& dir, std::size_t good_pairs,
                                         SourceStatus& status)
{
    auto sink = std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(256);
    auto previous = spdlog::default_logger();
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("replay-test", sink));
    {
        Rig rig(lockstep(dir, /*loop=*/true), 2);
        EXPECT_EQ(rig.source.start(rig.ring), 0) << rig.source.status().last_error;
        EXPECT_EQ(popPairs(rig.ring, 2 * good_pairs).size(), 2 * good_pairs);
        rig.source.stop();
        status = rig.source.status();
    }
    spdlog::set_default_logger(previous);
    return sink->last_formatted();
}

std::size_t linesWith(const std::vector<std::string>& lines, const std::string& needle)
{
    std::size_t n = 0;
    for (const std::string& line : lines)
        n += line.find(needle) != std::string::npos ? 1 : 0;
    return n;
}

TEST_F(ReplaySourceTest, DecompressionBombsAreRefusedUndecodedNamingTheirFile)
{
    const std::string dir = makeRecording(4);
    // 12000x12000 grey (144 MB decoded, a few hundred KB on disk): as the first pair's
    // left image, before the frame size is known, and as a later right image.
    test::writeDecompressionBomb(dir + "/left/000000.png", {12000, 12000});
    fs::copy_file(dir + "/left/000000.png", dir + "/right/000002.png",
                  fs::copy_options::overwrite_existing);
    const double rss_before_mb = peakRssMb();

    SourceStatus status;
    const std::vector<std::string> log = replayTwoPasses(dir, 2, status);
    EXPECT_LT(peakRssMb() - rss_before_mb, 50.0) << "a bomb was decoded";
    // Each bomb is named, with its size, once; the good images beside them never are.
    EXPECT_EQ(linesWith(log, "left/000000.png"), 1u);
    EXPECT_EQ(linesWith(log, "right/000002.png"), 1u);
    EXPECT_EQ(linesWith(log, "12000x12000"), 2u);
    EXPECT_EQ(linesWith(log, "right/000000.png"), 0u);
    EXPECT_EQ(linesWith(log, "left/000002.png"), 0u);
    EXPECT_GE(status.cameras[0].bad_frames, 2u);
    EXPECT_GE(status.cameras[1].bad_frames, 2u);
}

TEST_F(ReplaySourceTest, RowsPointingAtDevicesFifosOrTruncatedImagesAreBadFrames)
{
    const std::string dir = makeRecording(5);
    fs::remove(dir + "/left/000001.png");
    fs::create_symlink("/dev/zero", dir + "/left/000001.png");
    fs::remove(dir + "/right/000002.png");
    ASSERT_EQ(::mkfifo((dir + "/right/000002.png").c_str(), 0600), 0);
    // A truncated JPEG would decode into a grey-filled frame that passes for a good one.
    std::vector<uint8_t> jpeg = test::encode(pairs_[3].left, ".jpg");
    jpeg.resize(jpeg.size() / 2);
    test::writeBytes(dir + "/left/000003.png", jpeg);

    SourceStatus status;
    const std::vector<std::string> log = replayTwoPasses(dir, 2, status);
    EXPECT_EQ(linesWith(log, "left/000001.png"), 1u);
    EXPECT_EQ(linesWith(log, "not a regular file"), 2u);
    EXPECT_EQ(linesWith(log, "right/000002.png"), 1u);
    EXPECT_EQ(linesWith(log, "left/000003.png"), 1u);
    EXPECT_EQ(linesWith(log, "truncated JPEG"), 1u);
    EXPECT_GE(status.cameras[0].bad_frames, 4u); // 000001 and 000003, two passes
    EXPECT_GE(status.cameras[1].bad_frames, 2u); // 000002
}

TEST_F(ReplaySourceTest, WhatTheDecodersPrintGoesIntoTheLogNotToStderr)
{
    const std::string dir = makeRecording(4);
    // Damaged in the middle, with intact headers and ends: libpng fails with an error of
    // its own, libjpeg fills the damage in and says so.
    const auto damage = [](std::vector<uint8_t> bytes) {
        for (std::size_t i = bytes.size() / 3; i < bytes.size() * 2 / 3; i += 5)
            bytes[i] ^= 0x5a;
        return bytes;
    };
    test::writeBytes(dir + "/left/000001.png", damage(test::encode(pairs_[1].left, ".png")));
    test::writeBytes(dir + "/right/000002.png", damage(test::encode(pairs_[2].right, ".jpg")));

    // Everything written to fd 2 meanwhile goes to a file.
    const std::string stderr_path = tmp_.file("stderr.txt");
    std::fflush(stderr);
    const int saved = ::dup(STDERR_FILENO);
    const int file = ::open(stderr_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    ASSERT_GE(file, 0);
    ::dup2(file, STDERR_FILENO);
    ::close(file);
    SourceStatus status;
    const std::vector<std::string> log = replayTwoPasses(dir, 2, status);
    std::fflush(stderr);
    ::dup2(saved, STDERR_FILENO);
    ::close(saved);

    std::ifstream printed_file(stderr_path);
    const std::string printed(std::istreambuf_iterator<char>(printed_file), {});
    EXPECT_EQ(printed, "");
    EXPECT_EQ(linesWith(log, "left/000001.png"), 1u);
    EXPECT_EQ(linesWith(log, "libpng error"), 1u);
    EXPECT_EQ(linesWith(log, "right/000002.png"), 1u);
    EXPECT_EQ(linesWith(log, "corrupt: "), 1u);
    EXPECT_GE(status.cameras[0].bad_frames, 2u);
    EXPECT_GE(status.cameras[1].bad_frames, 2u);
}

TEST_F(ReplaySourceTest, NothingReadableFailsStartNamingThePath)
{
    const std::string dir = makeRecording(3);
    for (const char* name : {"000000.png", "000001.png", "000002.png"})
        test::writeGarbage(dir + "/left/" + name);
    Rig rig(lockstep(dir), 2);
    ReplaySource& source = rig.source;
    PairRing& ring = rig.ring;
    EXPECT_TRUE(source.frameSize().empty());
    EXPECT_EQ(source.start(ring), -EINVAL);
    const SourceStatus status = source.status();
    EXPECT_EQ(status.state, SourceState::Failed);
    EXPECT_NE(status.last_error.find(dir), std::string::npos) << status.last_error;
    EXPECT_NE(status.last_error.find("000000.png"), std::string::npos) << status.last_error;
    EXPECT_NE(status.last_error.find("not a readable image"), std::string::npos)
        << status.last_error;
    source.stop();
}

TEST_F(ReplaySourceTest, MissingImagesOrPathFailStartWithENOENT)
{
    const std::string dir = makeRecording(2);
    fs::remove_all(dir + "/right");
    PairRing ring(2);
    ReplaySource no_images(lockstep(dir));
    EXPECT_EQ(no_images.start(ring), -ENOENT);
    EXPECT_NE(no_images.status().last_error.find("missing"), std::string::npos)
        << no_images.status().last_error;

    const std::string nowhere = tmp_.file("no-such-recording");
    ReplaySource no_path(lockstep(nowhere));
    EXPECT_EQ(no_path.start(ring), -ENOENT);
    EXPECT_EQ(no_path.status().state, SourceState::Failed);
    EXPECT_NE(no_path.status().last_error.find(nowhere), std::string::npos)
        << no_path.status().last_error;
}

TEST_F(ReplaySourceTest, RecordingCalibrationIsExposed)
{
    pairs_ = test::tsukubaPairs(1);
    const std::string calibration = tmp_.file("rig.yaml");
    {
        std::ofstream out(calibration);
        out << "%YAML:1.0\n";
    }
    test::writeRecording(tmp_.file("rec"), pairs_, calibration);
    ReplaySource source(lockstep(tmp_.file("rec")));
    EXPECT_EQ(source.calibrationPath(), tmp_.file("rec/calibration.yaml"));
}

// A ROS 2 bag replays like a recording: every pair in order, lockstep, then finished; its
// camera_info is exposed for the service's calibration.
TEST_F(ReplaySourceTest, McapBagReplaysLikeARecording)
{
    pairs_ = test::tsukubaPairs(6);
    test::stampPairs(pairs_, 7'000'000'000, 40 * kMs);
    const std::string bag = tmp_.file("run.mcap");
    {
        McapRecordingWriter writer(bag);
        ros2::CameraInfo info;
        info.width = 96;
        info.height = 72;
        info.p = {100, 0, 48, -10, 0, 100, 36, 0, 0, 0, 1, 0};
        writer.setCameraInfo(info, info);
        for (const TestPair& p : pairs_)
            writer.write(p.left, p.right, p.left_stamp_ns, p.right_stamp_ns);
    } // closed by the destructor
    Rig rig(lockstep(bag), 2);
    ReplaySource& source = rig.source;
    EXPECT_EQ(source.frameSize(), cv::Size(96, 72));
    EXPECT_EQ(source.pairCount(), 6u);
    ASSERT_TRUE(source.bagCameraInfo().has_value());
    EXPECT_EQ(source.bagCameraInfo()->second.p[3], -10.0);
    ASSERT_EQ(source.start(rig.ring), 0) << source.status().last_error;
    std::vector<StereoPair> got = popPairs(rig.ring, 6);
    ASSERT_EQ(got.size(), 6u);
    for (std::size_t k = 0; k < got.size(); ++k)
        expectPairMatches(got[k], pairs_[k], k);
    ASSERT_TRUE(waitForState(source, SourceState::Finished));
    EXPECT_EQ(rig.ring.dropped(), 0u);
    got.clear();
    source.stop();

    // Topics that are not in the bag: start fails naming the bag and its image topics.
    ReplayOptions wrong = lockstep(bag);
    wrong.left_topic = "/cam/left";
    Rig bad(wrong, 2);
    EXPECT_EQ(bad.source.start(bad.ring), -EINVAL);
    EXPECT_NE(bad.source.status().last_error.find("/stereo/left/image_raw"), std::string::npos)
        << bad.source.status().last_error;
    bad.source.stop();
}

// The pairs (grey or BGR images) written as a CSV+PNG recording `path` and as a bag
// `path`.mcap, with their stamps; returns the two paths.
std::pair<std::string, std::string> writeRecordingAndBag(const std::string& path,
                                                         const std::vector<test::TestPair>& pairs)
{
    const std::string bag = path + ".mcap";
    RecordingWriter csv(path);
    McapRecordingWriter mcap(bag);
    for (const test::TestPair& pair : pairs) {
        csv.write(pair.left, pair.right, pair.left_stamp_ns, pair.right_stamp_ns);
        mcap.write(pair.left, pair.right, pair.left_stamp_ns, pair.right_stamp_ns);
    }
    mcap.close();
    return {path, bag};
}

// A colour recording, as a colour camera's are recorded (a colour left PNG, a bag's bgr8
// image): the left frame carries its colour exactly, its grey is the grey a grey replay
// of the same file gives, and the right camera's grey stays grey; keep_colour off or a
// grey recording give no colour.
TEST_F(ReplaySourceTest, ColourRecordingsKeepTheLeftCamerasColour)
{
    const cv::Mat tsukuba =
        cv::imread(test::sharedDataDir() + "/middlebury/tsukuba/im3.png", cv::IMREAD_COLOR);
    ASSERT_FALSE(tsukuba.empty());
    pairs_ = test::tsukubaPairs(3);
    test::stampPairs(pairs_, 7'000'000'000, 40 * kMs);
    std::vector<cv::Mat> colours;
    for (int k = 0; k < 3; ++k)
        colours.push_back(
            tsukuba(cv::Rect(12 * k, 6 * k, pairs_[0].left.cols, pairs_[0].left.rows)).clone());
    std::vector<test::TestPair> recorded = pairs_;
    for (int k = 0; k < 3; ++k)
        recorded[k].left = colours[k];
    const auto [dir, bag] = writeRecordingAndBag(tmp_.file("colour"), recorded);
    for (const std::string& path : {dir, bag}) {
        for (const bool keep : {true, false}) {
            SCOPED_TRACE(path + (keep ? " with colour" : " grey only"));
            ReplayOptions options = lockstep(path);
            options.keep_colour = keep;
            Rig rig(options, 4);
            ASSERT_EQ(rig.source.start(rig.ring), 0) << rig.source.status().last_error;
            std::vector<StereoPair> got = popPairs(rig.ring, 3);
            ASSERT_EQ(got.size(), 3u);
            for (int k = 0; k < 3; ++k) {
                const Frame& left = *got[k].left;
                // The grey of a colour PNG is libpng's, of a bgr8 image COLOR_BGR2GRAY.
                cv::Mat grey;
                if (path == dir)
                    grey = cv::imread(dir + "/left/" + fmt::format("{:06d}.png", k),
                                      cv::IMREAD_GRAYSCALE);
                else
                    cv::cvtColor(colours[k], grey, cv::COLOR_BGR2GRAY);
                EXPECT_TRUE(test::samePixels(left.image, grey)) << "pair " << k;
                EXPECT_TRUE(test::samePixels(got[k].right->image, pairs_[k].right));
                EXPECT_TRUE(got[k].right->colour.empty());
                if (keep) {
                    ASSERT_EQ(left.colour.type(), CV_8UC3);
                    EXPECT_EQ(cv::norm(left.colour, colours[k], cv::NORM_INF), 0.0) << "pair " << k;
                } else {
                    EXPECT_TRUE(left.colour.empty());
                }
            }
        }
    }

    // A grey recording: no colour plane at all.
    Rig grey(lockstep(makeRecording(2)), 4);
    ASSERT_EQ(grey.source.start(grey.ring), 0);
    std::vector<StereoPair> got = popPairs(grey.ring, 2);
    ASSERT_EQ(got.size(), 2u);
    EXPECT_TRUE(got[0].left->colour.empty());
}

// keep_right_colour (source.replay.colour both): the right frames carry their colour as
// the left ones do, their grey the grey of a grey replay; without it they stay grey.
TEST_F(ReplaySourceTest, BothKeepsTheRightCamerasColourToo)
{
    const std::string tsukuba = test::sharedDataDir() + "/middlebury/tsukuba/";
    const cv::Mat left = cv::imread(tsukuba + "im3.png", cv::IMREAD_COLOR);
    const cv::Mat right = cv::imread(tsukuba + "im4.png", cv::IMREAD_COLOR);
    ASSERT_FALSE(left.empty());
    ASSERT_FALSE(right.empty());
    std::vector<test::TestPair> recorded(2, test::TestPair{left, right, 0, 0});
    test::stampPairs(recorded, 1'000'000'000, 40 * kMs);
    const auto [dir, bag] = writeRecordingAndBag(tmp_.file("both"), recorded);
    for (const std::string& path : {dir, bag}) {
        for (const bool both : {true, false}) {
            SCOPED_TRACE(path + (both ? " both in colour" : " left in colour"));
            ReplayOptions options = lockstep(path);
            options.keep_right_colour = both;
            Rig rig(options, 4);
            ASSERT_EQ(rig.source.start(rig.ring), 0) << rig.source.status().last_error;
            std::vector<StereoPair> got = popPairs(rig.ring, 2);
            ASSERT_EQ(got.size(), 2u);
            cv::Mat grey;
            if (path == dir)
                grey = cv::imread(dir + "/right/000001.png", cv::IMREAD_GRAYSCALE);
            else
                cv::cvtColor(right, grey, cv::COLOR_BGR2GRAY);
            const Frame& frame = *got[1].right;
            EXPECT_TRUE(test::samePixels(frame.image, grey));
            EXPECT_EQ(got[1].left->colour.type(), CV_8UC3);
            if (both) {
                ASSERT_EQ(frame.colour.type(), CV_8UC3);
                EXPECT_EQ(cv::norm(frame.colour, right, cv::NORM_INF), 0.0);
            } else {
                EXPECT_TRUE(frame.colour.empty());
            }
        }
    }
}

// Issue 23: Image messages that lie about their size, mid-replay, after good pairs: the
// first faulted in cvtColor (SIGSEGV), the second threw out of the replay thread
// (std::terminate), the third (another size) went to the worker. Each is now a bad frame,
// counted and logged, and the replay goes on.
TEST_F(ReplaySourceTest, McapImagesThatLieAreSkippedAndTheReplayGoesOn)
{
    pairs_ = test::tsukubaPairs(9);
    test::stampPairs(pairs_, 7'000'000'000, 40 * kMs);
    std::vector<std::pair<test::ImageMessage, test::ImageMessage>> messages;
    for (const TestPair& p : pairs_)
        messages.emplace_back(test::monoMessage(p.left, p.left_stamp_ns),
                              test::monoMessage(p.right, p.right_stamp_ns));
    // Pair 5: rgba8, 2^30 x 1, step 0, 64 bytes (2^30 * 4 is 0 in 32 bits).
    test::ImageMessage& overflow = messages[5].first;
    overflow.encoding = "rgba8";
    overflow.width = 1u << 30;
    overflow.height = 1;
    overflow.step = 0;
    overflow.data.assign(64, '\x40');
    // Pair 6, right: rgb8, 0x55555556 x 1, step 2 (3 * width is 2 in 32 bits).
    test::ImageMessage& wrapped = messages[6].second;
    wrapped.encoding = "rgb8";
    wrapped.width = 0x55555556u;
    wrapped.height = 1;
    wrapped.step = 2;
    wrapped.data.assign(64, '\x40');
    // Pair 7: a truthful pair of another size than the replay's.
    const std::vector<TestPair> larger = test::tsukubaPairs(1, cv::Size(192, 144));
    ASSERT_EQ(larger.size(), 1u);
    messages[7] = {test::monoMessage(larger[0].left, pairs_[7].left_stamp_ns),
                   test::monoMessage(larger[0].right, pairs_[7].right_stamp_ns)};
    const std::string bag = tmp_.file("lies.mcap");
    test::writeStereoBag(bag, messages);

    auto sink = std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(64);
    auto previous = spdlog::default_logger();
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("replay-test", sink));
    std::vector<std::size_t> delivered;
    SourceStatus status;
    {
        Rig rig(lockstep(bag), 2);
        ASSERT_EQ(rig.source.start(rig.ring), 0) << rig.source.status().last_error;
        for (std::optional<StereoPair> pair; (pair = rig.ring.pop());) {
            EXPECT_EQ(pair->left->image.size(), cv::Size(96, 72));
            EXPECT_EQ(pair->right->image.size(), cv::Size(96, 72));
            delivered.push_back(pair->index);
            if (delivered.size() == 6)
                break;
        }
        EXPECT_TRUE(waitForState(rig.source, SourceState::Finished));
        status = rig.source.status();
    }
    spdlog::set_default_logger(previous);
    EXPECT_EQ(delivered, (std::vector<std::size_t>{0, 1, 2, 3, 4, 8}));
    EXPECT_EQ(status.cameras[0].bad_frames, 2u); // pairs 5 and 7
    EXPECT_EQ(status.cameras[1].bad_frames, 1u); // pair 6
    std::string log;
    for (const std::string& line : sink->last_formatted())
        log += line;
    EXPECT_NE(log.find("1073741824x1 pixels, more than a frame may have"), std::string::npos)
        << log;
    EXPECT_NE(log.find("1431655766x1 pixels, more than a frame may have"), std::string::npos)
        << log;
    EXPECT_NE(log.find("is 192x144, 96x72 expected"), std::string::npos) << log;
}

// Issue 23: a bag whose stamps are all equal replayed as fast as it decoded (102 fps for a
// 10 fps source). A stamp that repeats the one before now comes one frame period later.
TEST_F(ReplaySourceTest, StampsThatRepeatComeOneFramePeriodApart)
{
    pairs_ = test::tsukubaPairs(6);
    test::stampPairs(pairs_, 7'000'000'000, 0); // every left stamp the same
    const std::string dir = tmp_.file("frozen");
    test::writeRecording(dir, pairs_);
    ReplayOptions options = paced(dir, false, 10);
    options.fps = 50.0; // no step forward to measure: the nominal rate's period, 20 ms
    Rig rig(options, 8);
    const int64_t started_ns = monotonicNowNs();
    ASSERT_EQ(rig.source.start(rig.ring), 0);
    const std::vector<StereoPair> got = popPairs(rig.ring, 6);
    ASSERT_EQ(got.size(), 6u);
    for (std::size_t k = 0; k < got.size(); ++k)
        EXPECT_GE(got[k].stampNs() - started_ns, static_cast<int64_t>(k) * 20 * kMs)
            << "pair " << k;
}

// Issue 23: with the process out of descriptors the replay could not open its frames and
// stopped for good ("no pair readable in a whole pass"). It must say so, try again, and go
// on once descriptors are free again.
TEST_F(ReplaySourceTest, RecoversWhenDescriptorsReturn)
{
    if (test::sanitizersNeedDescriptors())
        GTEST_SKIP() << "UBSan's vptr check needs descriptors of its own (a pipe)";
    Rig rig(paced(makeRecording(3, 20 * kMs), true, 8), 4);
    ASSERT_EQ(rig.source.start(rig.ring), 0);
    // Drains the ring (the pairs go back to the pool) until `done` or about 15 s.
    const auto drainUntil = [&](const auto& done) {
        for (int i = 0; i < 3000; ++i) {
            while (rig.ring.tryPop()) {
            }
            if (done())
                return true;
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        return false;
    };
    ASSERT_TRUE(drainUntil([&] { return rig.source.status().pairs >= 3; }));

    test::DescriptorExhaustion exhaustion;
    const bool failed =
        drainUntil([&] { return rig.source.status().state == SourceState::Failed; });
    const std::string error = rig.source.status().last_error;
    exhaustion.release();
    ASSERT_TRUE(failed) << "the replay went on without descriptors?";
    EXPECT_NE(error.find("trying again"), std::string::npos) << error;

    const uint64_t before = rig.source.status().pairs;
    EXPECT_TRUE(drainUntil([&] {
        const SourceStatus s = rig.source.status();
        return s.state == SourceState::Running && s.pairs >= before + 3;
    })) << "the replay did not recover: "
        << rig.source.status().last_error;
    EXPECT_TRUE(rig.source.status().last_error.empty());
}

} // namespace
} // namespace stereod
