// The log rate limiter: one message per key and interval, the held-back ones counted and
// reported, keys independent, the table bounded, and what reaches the log.

#include <memory>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include "daemon/log_limiter.hpp"

namespace stereod {
namespace {

constexpr int64_t kSecondNs = 1'000'000'000;

// Sends spdlog's default logger into a string for the test's lifetime.
class CapturedLog {
  public:
    CapturedLog()
        : previous_(spdlog::default_logger()),
          logger_(std::make_shared<spdlog::logger>(
              "captured", std::make_shared<spdlog::sinks::ostream_sink_st>(text_)))
    {
        logger_->set_pattern("%l %v");
        logger_->set_level(spdlog::level::trace);
        spdlog::set_default_logger(logger_);
    }
    ~CapturedLog() { spdlog::set_default_logger(previous_); }
    CapturedLog(const CapturedLog&) = delete;
    CapturedLog& operator=(const CapturedLog&) = delete;

    std::string text() const { return text_.str(); }

  private:
    std::ostringstream text_;
    std::shared_ptr<spdlog::logger> previous_;
    std::shared_ptr<spdlog::logger> logger_;
};

TEST(LogLimiter, OneMessagePerKeyAndIntervalAndTheRestCounted)
{
    LogLimiter limiter(5 * kSecondNs);
    const int64_t t0 = 100 * kSecondNs;
    EXPECT_TRUE(limiter.admit("camera.read", t0).log);
    // A camera failing at 30 fps for 4.9 s: all held back.
    int held_back = 0;
    for (int64_t t = t0 + kSecondNs / 30; t < t0 + 5 * kSecondNs; t += kSecondNs / 30) {
        const LogLimiter::Decision decision = limiter.admit("camera.read", t);
        EXPECT_FALSE(decision.log) << "at " << t - t0 << " ns";
        ++held_back;
    }
    ASSERT_GT(held_back, 140);
    // Once the interval has passed, the next one goes through and carries the count.
    const LogLimiter::Decision next = limiter.admit("camera.read", t0 + 5 * kSecondNs);
    EXPECT_TRUE(next.log);
    EXPECT_EQ(next.suppressed, static_cast<uint64_t>(held_back));
    // The count starts over.
    const LogLimiter::Decision later = limiter.admit("camera.read", t0 + 11 * kSecondNs);
    EXPECT_TRUE(later.log);
    EXPECT_EQ(later.suppressed, 0u);
}

TEST(LogLimiter, KeysAreIndependent)
{
    LogLimiter limiter(kSecondNs);
    EXPECT_TRUE(limiter.admit("a", 10).log);
    EXPECT_TRUE(limiter.admit("b", 11).log);
    EXPECT_FALSE(limiter.admit("a", 12).log);
    EXPECT_FALSE(limiter.admit("b", 13).log);
    EXPECT_TRUE(limiter.admit("c", 14).log);
    EXPECT_EQ(limiter.admit("a", 10 + kSecondNs).suppressed, 1u);
}

TEST(LogLimiter, FullTableGivesWayToTheLeastRecentlyLoggedKey)
{
    LogLimiter limiter(kSecondNs);
    for (std::size_t i = 0; i < LogLimiter::kMaxKeys; ++i)
        ASSERT_TRUE(limiter.admit("key" + std::to_string(i), 1 + static_cast<int64_t>(i)).log);
    // Every key is still limited...
    EXPECT_FALSE(limiter.admit("key5", 100).log);
    // ...and one more key takes the place of the oldest (key0), which then starts afresh.
    EXPECT_TRUE(limiter.admit("another", 200).log);
    EXPECT_FALSE(limiter.admit("another", 300).log);
    EXPECT_TRUE(limiter.admit("key0", 400).log);
    // Over-long keys are cut, not refused.
    const std::string long_key(200, 'k');
    EXPECT_TRUE(limiter.admit(long_key, 500).log);
    EXPECT_FALSE(limiter.admit(long_key, 600).log);
}

TEST(LogLimiter, LogWritesTheMessageWithTheRepeatCount)
{
    CapturedLog log;
    LogLimiter limiter(kSecondNs);
    for (int frame = 0; frame < 10; ++frame)
        limiter.log(spdlog::level::err, "worker.pair_failed", 1 + frame * 1000,
                    "frame {}: cannot process: {}", frame, "bad image");
    limiter.log(spdlog::level::err, "worker.pair_failed", 2 * kSecondNs,
                "frame {}: cannot process: {}", 10, "bad image");
    EXPECT_EQ(log.text(), "error frame 0: cannot process: bad image\n"
                          "error frame 10: cannot process: bad image (repeated 9 times)\n");
}

TEST(LogLimiter, FlushReportsWhatWasHeldBackOnceTheKeyFallsQuiet)
{
    CapturedLog log;
    LogLimiter limiter(kSecondNs);
    limiter.log(spdlog::level::warn, "client.too_many", 1, "refused client {}", 1);
    limiter.log(spdlog::level::warn, "client.too_many", 2, "refused client {}", 2);
    limiter.log(spdlog::level::warn, "client.too_many", 3, "refused client {}", 3);
    limiter.flush(kSecondNs / 2); // within the interval: nothing yet
    EXPECT_EQ(log.text(), "warning refused client 1\n");
    limiter.flush(2 * kSecondNs);
    EXPECT_EQ(log.text(),
              "warning refused client 1\nwarning client.too_many: repeated 2 times in the last "
              "2.0 s\n");
    limiter.flush(10 * kSecondNs); // nothing left to report
    EXPECT_EQ(log.text(),
              "warning refused client 1\nwarning client.too_many: repeated 2 times in the last "
              "2.0 s\n");
}

TEST(LogLimiter, MessagesBelowTheLogLevelAreStillCounted)
{
    CapturedLog log;
    spdlog::set_level(spdlog::level::err);
    LogLimiter limiter(kSecondNs);
    limiter.log(spdlog::level::warn, "k", 1, "hidden");
    spdlog::set_level(spdlog::level::trace);
    limiter.log(spdlog::level::warn, "k", 2, "held back");
    limiter.log(spdlog::level::warn, "k", 1 + kSecondNs, "shown");
    EXPECT_EQ(log.text(), "warning shown (repeated 1 time)\n");
}

} // namespace
} // namespace stereod
