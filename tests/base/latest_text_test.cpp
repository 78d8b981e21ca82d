// The latest text a capture thread writes without waiting: whole or not at all.
#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "base/latest_text.hpp"

namespace stereod {
namespace {

TEST(LatestText, EmptyUntilWrittenThenTheLastText)
{
    LatestText<32> text;
    EXPECT_EQ(text.read(), "");
    text.write("bytesused smaller than the image");
    EXPECT_EQ(text.read(), "bytesused smaller than the image");
    text.write("short");
    EXPECT_EQ(text.read(), "short");
}

TEST(LatestText, ALongerTextIsCutAtTheCapacity)
{
    LatestText<8> text;
    text.write("0123456789");
    EXPECT_EQ(text.read(), "01234567");
}

// The capture thread's case: one writer that never waits, readers on other threads. A
// reader gets one of the texts whole, never a mix of two (nor, under ThreadSanitizer, a
// data race).
TEST(LatestText, ReadersNeverSeeTwoTextsMixed)
{
    LatestText<64> text;
    const std::string a(40, 'a');
    const std::string b = "a corrupt MJPEG frame: no end-of-image marker";
    std::atomic<bool> stop{false};
    std::thread writer([&] {
        for (int i = 0; !stop.load(std::memory_order_relaxed); ++i)
            text.write(i % 2 == 0 ? a : b);
    });
    std::vector<std::thread> readers;
    std::atomic<int> mixed{0};
    std::atomic<int> reads{0};
    for (int r = 0; r < 2; ++r) {
        readers.emplace_back([&] {
            for (int i = 0; i < 20000; ++i) {
                const std::string seen = text.read();
                if (!seen.empty() && seen != a && seen != b)
                    mixed.fetch_add(1);
                reads.fetch_add(1);
            }
        });
    }
    for (std::thread& reader : readers)
        reader.join();
    stop.store(true);
    writer.join();
    EXPECT_EQ(reads.load(), 40000);
    EXPECT_EQ(mixed.load(), 0);
}

} // namespace
} // namespace stereod
