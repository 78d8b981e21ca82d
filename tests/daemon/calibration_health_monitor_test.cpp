// The calibration health monitor as the service runs it: pairs handed over one after the
// other, measured on the monitor's own thread. Checks are driven back to back (the
// monitor's interval is a nanosecond and each pair is offered once the last check is
// done), never by sleeping.
//  - The same pair checked again and again costs the same each time: the same matches,
//    and no memory that grows with the number of checks.

#include <chrono>
#include <cstdio>
#include <string>

#include <gtest/gtest.h>
#include <malloc.h>
#include <opencv2/imgcodecs.hpp>

#include "capture/frame.hpp"
#include "daemon/calibration_health_monitor.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;

const std::string kData = test::sharedDataDir() + "/";

// Bytes the heap has handed out and not taken back.
size_t heapInUse()
{
    return ::mallinfo2().uordblks;
}

// Offers the pair and waits until the monitor has checked it.
HealthReport checkOnce(CalibrationHealthMonitor& monitor, const cv::Mat& left, const cv::Mat& right,
                       uint64_t checks_before)
{
    EXPECT_TRUE(monitor.due(monotonicNowNs()));
    monitor.offer(left, right, monotonicNowNs());
    EXPECT_TRUE(monitor.waitForChecks(checks_before + 1, 60s))
        << "check " << checks_before + 1 << " not done within 60 s";
    return monitor.report();
}

TEST(CalibrationHealthMonitor, RepeatedChecksOfOnePairCostTheSame)
{
    const cv::Mat left =
        cv::imread(kData + "middlebury2014/Adirondack/im0.png", cv::IMREAD_GRAYSCALE);
    const cv::Mat right =
        cv::imread(kData + "middlebury2014/Adirondack/im1.png", cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(left.empty() || right.empty());
    // Adirondack's calib.txt: f 1038.018 px, cx 322.037, cy 243.393, doffs 53.271.
    const StereoCalibration rig =
        makeRectifiedCalibration(left.size(), 1038.018, 0.176252, 322.037, 243.393, 53.271);
    CalibrationHealthMonitor monitor(rig.rectified, 1e-9);
    // A few checks first: the detector's and matcher's buffers reach their size.
    constexpr int kWarmUp = 5;
    constexpr int kChecks = 40;
    HealthReport first;
    size_t heap_after_warm_up = 0;
    for (int i = 0; i < kChecks; ++i) {
        const HealthReport report = checkOnce(monitor, left, right, static_cast<uint64_t>(i));
        ASSERT_EQ(report.checks, static_cast<uint64_t>(i + 1));
        if (i == 0) {
            first = report;
            ASSERT_GT(first.matches, 100);
        }
        EXPECT_EQ(report.matches, first.matches) << "check " << i + 1;
        EXPECT_EQ(report.state, first.state) << "check " << i + 1;
        if (i + 1 == kWarmUp)
            heap_after_warm_up = heapInUse();
    }
    const double growth_kb =
        (static_cast<double>(heapInUse()) - static_cast<double>(heap_after_warm_up)) / 1024.0;
    std::printf("[health] %d checks of one pair: %d matches each, heap %+.0f KB over the last "
                "%d checks\n",
                kChecks, first.matches, growth_kb, kChecks - kWarmUp);
    // The checks keep nothing of each other but a few numbers for the trend.
    EXPECT_LT(growth_kb, 256.0);
}

} // namespace
} // namespace stereod
