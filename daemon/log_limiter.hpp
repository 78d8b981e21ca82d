#pragma once
// Rate limiting of repeated log messages: a camera that fails every frame, a client that
// reconnects in a loop or a stream of oversized requests must not flood the journal.
//
// Messages are grouped by a key, a short constant naming the kind of message
// ("worker.pair_failed"), not by their text (which carries frame numbers and such).
// Per key, at most one message per interval is logged; the ones held back are counted,
// and the next one that is logged says how many were held back: "... (repeated 49 times)".
// When a key falls quiet, flush() logs the count of the last ones held back, so that
// nothing is silently lost.
//
// Thread contract: thread-bound; each thread that logs (the worker, the I/O thread) has
// its own limiter. No allocation after a key's first use: keys live in a fixed table
// (the least recently logged key gives way when it is full).

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>

#include <spdlog/spdlog.h>

namespace stereod {

class LogLimiter {
  public:
    // Keys tracked at once, and the longest key kept (longer ones are cut, which only
    // merges keys that share their first kMaxKeyBytes bytes).
    static constexpr std::size_t kMaxKeys = 32;
    static constexpr std::size_t kMaxKeyBytes = 47;

    // `interval_ns`: at most one message per key in this time (CLOCK_MONOTONIC ns).
    explicit LogLimiter(int64_t interval_ns = 5'000'000'000) noexcept;

    struct Decision {
        bool log = false;        // log this message
        uint64_t suppressed = 0; // when logged: messages of this key held back before it
    };

    // Whether a message of `key` at `now_ns` is to be logged; counts it if not. `level`
    // is the level flush() reports the key's held-back messages at.
    Decision admit(std::string_view key, int64_t now_ns,
                   spdlog::level::level_enum level = spdlog::level::info) noexcept;

    // Logs the message at `level` if admit() lets it through, with " (repeated K times)"
    // appended when K messages of the key were held back before it.
    template <typename... Args>
    void log(spdlog::level::level_enum level, std::string_view key, int64_t now_ns,
             fmt::format_string<Args...> format, Args&&... args)
    {
        const Decision decision = admit(key, now_ns, level);
        if (!decision.log || !spdlog::should_log(level))
            return;
        std::string text = fmt::format(format, std::forward<Args>(args)...);
        if (decision.suppressed > 0)
            text += fmt::format(" (repeated {} time{})", decision.suppressed,
                                decision.suppressed == 1 ? "" : "s");
        spdlog::log(level, "{}", text);
    }

    // For each key whose messages were held back and whose interval has passed since
    // its last logged message: logs "KEY: repeated K times in the last S s" at the level
    // of that key's messages, and resets its count. Call it now and then (each tick).
    void flush(int64_t now_ns);

    int64_t intervalNs() const noexcept { return interval_ns_; }

  private:
    struct Entry {
        std::array<char, kMaxKeyBytes + 1> key{}; // NUL-terminated; empty: unused
        int64_t last_logged_ns = 0;
        uint64_t suppressed = 0;
        spdlog::level::level_enum level = spdlog::level::info;
    };

    Entry& entryFor(std::string_view key) noexcept;

    int64_t interval_ns_;
    std::array<Entry, kMaxKeys> entries_{};
};

} // namespace stereod
