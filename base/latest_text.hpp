#pragma once
// The latest short text one thread writes and any thread reads: "what was wrong with
// the last bad frame". The writer is a capture thread, which takes no lock and
// allocates nothing per frame (docs/architecture.md), so it never waits for a reader:
// a sequence counter (a seqlock) tells a reader that copied while the writer wrote to
// copy again. The characters are atomics, so the race a seqlock tolerates is not a data
// race.
//
// One writer thread; read() from any thread (it allocates the string it returns). A
// text longer than the capacity is cut, never refused.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace stereod {

template <std::size_t Capacity> class LatestText {
  public:
    // Writer thread only. No lock, no allocation.
    void write(std::string_view text) noexcept
    {
        const std::size_t size = text.size() < Capacity ? text.size() : Capacity;
        const uint64_t sequence = sequence_.load(std::memory_order_relaxed);
        sequence_.store(sequence + 1, std::memory_order_relaxed); // odd: writing
        std::atomic_thread_fence(std::memory_order_release);
        for (std::size_t i = 0; i < size; ++i)
            chars_[i].store(text[i], std::memory_order_relaxed);
        size_.store(size, std::memory_order_relaxed);
        sequence_.store(sequence + 2, std::memory_order_release); // even: whole
    }

    // Any thread: the text as last written whole ("" before the first write).
    std::string read() const
    {
        std::string out;
        out.reserve(Capacity);
        for (;;) {
            const uint64_t before = sequence_.load(std::memory_order_acquire);
            if (before % 2 == 0) {
                const std::size_t size = size_.load(std::memory_order_relaxed);
                out.resize(size);
                for (std::size_t i = 0; i < size; ++i)
                    out[i] = chars_[i].load(std::memory_order_relaxed);
                std::atomic_thread_fence(std::memory_order_acquire);
                if (sequence_.load(std::memory_order_relaxed) == before)
                    return out;
            }
        }
    }

  private:
    std::atomic<uint64_t> sequence_{0};
    std::atomic<std::size_t> size_{0};
    std::array<std::atomic<char>, Capacity> chars_{};
};

} // namespace stereod
