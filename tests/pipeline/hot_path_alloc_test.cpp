// No heap allocation per frame in steady state, for the per-frame calls of the rectify
// stage and the depth snapshot: after the first call, further calls allocate neither
// cv::Mat buffers nor anything through operator new, on any thread.
//
// The counting replacement of the global operator new and the counting cv::MatAllocator
// are the benchmark's (bench/alloc_counter.cpp), compiled into this executable only:
// replacing operator new affects the whole program, so nothing else is tested here.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "bench/alloc_counter.hpp"
#include "bench/bench_data.hpp"
#include "pipeline/depth_io.hpp"
#include "pipeline/rectifier.hpp"

namespace stereod {
namespace {

constexpr int kFrames = 20;

// Has every thread of OpenCV's pool run a job, as the service's first frames do: a
// thread's first job sets up its state (allocations), and on a busy machine a worker can
// wake only after the first calls have finished without it, then join one inside the
// measured window. Each of the stripes, one per thread, waits until all have started, so
// that no thread takes two.
void startEveryPoolThread()
{
    const int threads = cv::getNumThreads();
    std::atomic<int> started{0};
    cv::parallel_for_(
        cv::Range(0, threads),
        [&](const cv::Range& stripes) {
            started.fetch_add(stripes.end - stripes.start);
            const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(5);
            while (started.load() < threads && std::chrono::steady_clock::now() < give_up)
                std::this_thread::yield();
        },
        threads);
    ASSERT_EQ(started.load(), threads) << "a thread of OpenCV's pool never started";
}

class HotPathAllocations : public ::testing::Test {
  protected:
    static void SetUpTestSuite() { bench::installCountingMatAllocator(); }
};

// The counters see what they are meant to see, so that the zeros below mean something.
TEST_F(HotPathAllocations, CountersSeeBothKindsOfAllocation)
{
    const bench::AllocationWindow window;
    const cv::Mat image(48, 64, CV_8UC1);
    EXPECT_EQ(window.matAllocations(), 1u);
    EXPECT_GE(window.cppAllocations(), 1u); // the buffer's header (UMatData)
}

TEST_F(HotPathAllocations, RectifierAllocatesNothingAfterTheFirstFrame)
{
    const cv::Size size(640, 480);
    const StereoCalibration calibration = bench::makePlausibleRigCalibration(size);
    const bench::ImagePair raw =
        bench::simulateRawPair(calibration, bench::loadScene(bench::scenes()[0], size));
    const Rectifier rectifier(calibration);
    ASSERT_TRUE(rectifier.remaps());

    // The first frame creates the outputs (and OpenCV's thread pool starts its workers).
    cv::Mat left, right;
    rectifier.rectifyLeft(raw.left, left);
    rectifier.rectifyRight(raw.right, right);
    startEveryPoolThread();
    const uint8_t* left_buffer = left.data;
    const uint8_t* right_buffer = right.data;

    uint64_t cpp = 0;
    uint64_t mat = 0;
    {
        const bench::AllocationWindow window;
        for (int frame = 0; frame < kFrames; ++frame) {
            rectifier.rectifyLeft(raw.left, left);
            rectifier.rectifyRight(raw.right, right);
        }
        cpp = window.cppAllocations();
        mat = window.matAllocations();
    }
    EXPECT_EQ(cpp, 0u) << "operator new calls in " << kFrames << " frames";
    EXPECT_EQ(mat, 0u) << "new cv::Mat buffers in " << kFrames << " frames";
    EXPECT_EQ(left.data, left_buffer);
    EXPECT_EQ(right.data, right_buffer);
    EXPECT_GT(cv::countNonZero(left), static_cast<int>(left.total() / 2));
}

TEST_F(HotPathAllocations, ColourRectifyAllocatesNothingAfterTheFirstFrame)
{
    const cv::Size size(640, 480);
    const StereoCalibration calibration = bench::makePlausibleRigCalibration(size);
    const bench::ImagePair raw =
        bench::simulateRawPair(calibration, bench::loadScene(bench::scenes()[0], size));
    cv::Mat colour;
    cv::Mat planes[] = {raw.left, 255 - raw.left, raw.left / 2};
    cv::merge(planes, 3, colour);
    const Rectifier rectifier(calibration);

    cv::Mat out;
    rectifier.rectifyLeft(colour, out);
    startEveryPoolThread();
    const uint8_t* buffer = out.data;
    uint64_t cpp = 0;
    uint64_t mat = 0;
    {
        const bench::AllocationWindow window;
        for (int frame = 0; frame < kFrames; ++frame)
            rectifier.rectifyLeft(colour, out);
        cpp = window.cppAllocations();
        mat = window.matAllocations();
    }
    EXPECT_EQ(cpp, 0u) << "operator new calls in " << kFrames << " frames";
    EXPECT_EQ(mat, 0u) << "new cv::Mat buffers in " << kFrames << " frames";
    EXPECT_EQ(out.data, buffer);
    EXPECT_EQ(out.type(), CV_8UC3);
}

TEST_F(HotPathAllocations, DepthToMillimetresAllocatesNothingIntoAPreparedBuffer)
{
    cv::Mat depth_m(480, 640, CV_32FC1);
    cv::randu(depth_m, -1.0, 70.0);
    cv::Mat depth_mm(depth_m.size(), CV_16UC1);
    const uint8_t* buffer = depth_mm.data;
    // The first calls start OpenCV's thread pool's workers, as the service's first frames
    // do; startEveryPoolThread() makes sure of it.
    for (int frame = 0; frame < kFrames; ++frame)
        depthToMillimetres(depth_m, depth_mm);
    startEveryPoolThread();

    uint64_t cpp = 0;
    uint64_t mat = 0;
    {
        const bench::AllocationWindow window;
        for (int frame = 0; frame < kFrames; ++frame)
            depthToMillimetres(depth_m, depth_mm);
        cpp = window.cppAllocations();
        mat = window.matAllocations();
    }
    EXPECT_EQ(cpp, 0u);
    EXPECT_EQ(mat, 0u);
    EXPECT_EQ(depth_mm.data, buffer);
    EXPECT_GT(cv::countNonZero(depth_mm), static_cast<int>(depth_mm.total() / 2));
}

} // namespace
} // namespace stereod
