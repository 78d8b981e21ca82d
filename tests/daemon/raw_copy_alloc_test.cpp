// The worker's raw-frame copy: while raw frames are wanted, the pair as captured reaches
// the published slot byte for byte with each camera's own stamp, and in steady state
// neither the copy nor the rest of the uncalibrated worker's frame allocates anything.
//
// The counting replacement of the global operator new and the counting cv::MatAllocator
// are the benchmark's (bench/alloc_counter.cpp), compiled into this executable only.

#include <chrono>
#include <cstdint>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "bench/alloc_counter.hpp"
#include "capture/frame_pool.hpp"
#include "daemon/publisher.hpp"
#include "daemon/worker.hpp"
#include "protocol/events.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

const std::string kTsukuba = test::tsukubaDir();
constexpr int kWarmUpFrames = 6; // every slot of the triple buffer filled twice
constexpr int kFrames = 20;

class RawCopy : public ::testing::Test {
  protected:
    static void SetUpTestSuite() { bench::installCountingMatAllocator(); }

    void SetUp() override
    {
        left_ = cv::imread(kTsukuba + "/im3.png", cv::IMREAD_GRAYSCALE);
        right_ = cv::imread(kTsukuba + "/im4.png", cv::IMREAD_GRAYSCALE);
        ASSERT_FALSE(left_.empty());
        ASSERT_FALSE(right_.empty());
    }

    // A pair from the pool, filled with the images (darker by `shade`) and stamps.
    StereoPair makePair(FramePool& pool, uint64_t index, int shade)
    {
        StereoPair pair;
        pair.index = index;
        pair.left = pool.acquire();
        pair.right = pool.acquire();
        left_.convertTo(pair.left->image, CV_8U, 1.0, -shade);
        right_.convertTo(pair.right->image, CV_8U, 1.0, -shade);
        pair.left->stamp_ns = 1000 + static_cast<int64_t>(index);
        pair.right->stamp_ns = 2000 + static_cast<int64_t>(index);
        pair.left->source_stamp_ns = 5'000'000'000 + static_cast<int64_t>(index) * 10;
        pair.right->source_stamp_ns = 5'000'000'007 + static_cast<int64_t>(index) * 10;
        return pair;
    }

    cv::Mat left_, right_;
};

TEST_F(RawCopy, CopiesThePairAsCapturedWithItsOwnStamps)
{
    FramePool pool(2, left_.size());
    const StereoPair pair = makePair(pool, 3, 9);
    RawPair raw;
    copyRawPair(pair, raw);
    ASSERT_TRUE(raw.present);
    EXPECT_EQ(cv::norm(raw.left, pair.left->image, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(raw.right, pair.right->image, cv::NORM_INF), 0.0);
    EXPECT_EQ(raw.left_stamp_ns, 5'000'000'030);
    EXPECT_EQ(raw.right_stamp_ns, 5'000'000'037);

    StereoPair half;
    half.left = pool.acquire();
    copyRawPair(half, raw);
    EXPECT_FALSE(raw.present);
}

TEST_F(RawCopy, UncalibratedWorkerAllocatesNothingPerFrameInSteadyState)
{
    FramePool pool(8, left_.size());
    PairRing ring(4);
    Publisher publisher;
    Worker worker(ring, publisher, nullptr, 1000.0);
    worker.start();
    publisher.wantRawUntil(monotonicNowNs() + 600'000'000'000);

    std::string event; // the I/O thread's header buffer, kept from frame to frame
    const auto runFrame = [&](uint64_t index) {
        const uint64_t before = publisher.publishedCount();
        ring.push(makePair(pool, index, static_cast<int>(index % 7)));
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
        while (publisher.publishedCount() == before && std::chrono::steady_clock::now() < deadline)
            std::this_thread::yield();
        const PublishedFrame* frame = publisher.latest();
        if (frame == nullptr)
            return false;
        RawEventHeader header;
        header.frame = frame->result.frame;
        header.left_stamp_ns = frame->raw.left_stamp_ns;
        header.right_stamp_ns = frame->raw.right_stamp_ns;
        header.width = frame->raw.left.cols;
        header.height = frame->raw.left.rows;
        event.clear();
        appendRawEventHeader(event, header, 0);
        return frame->raw.present && frame->result.frame == index &&
               frame->result.reading.reason == NoReadingReason::Uncalibrated &&
               frame->raw.left_stamp_ns == 5'000'000'000 + static_cast<int64_t>(index) * 10;
    };

    // The images are made before counting: convertTo into a pool frame allocates nothing,
    // but the first frames of a size give the slots their buffers.
    for (uint64_t index = 0; index < kWarmUpFrames; ++index)
        ASSERT_TRUE(runFrame(index)) << "frame " << index;
    uint64_t cpp = 0;
    uint64_t mat = 0;
    bool all_good = true;
    {
        const bench::AllocationWindow window;
        for (uint64_t index = kWarmUpFrames; index < kWarmUpFrames + kFrames; ++index)
            all_good = runFrame(index) && all_good;
        cpp = window.cppAllocations();
        mat = window.matAllocations();
    }
    EXPECT_TRUE(all_good);
    EXPECT_EQ(cpp, 0u) << "operator new calls in " << kFrames << " frames";
    EXPECT_EQ(mat, 0u) << "new cv::Mat buffers in " << kFrames << " frames";
    EXPECT_NE(event.find("\"event\":\"raw\""), std::string::npos) << event;
}

} // namespace
} // namespace stereod
