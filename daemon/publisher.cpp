#include "daemon/publisher.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <system_error>

#include <sys/eventfd.h>
#include <unistd.h>

#include "base/system_error.hpp"
#include "capture/frame.hpp"

namespace stereod {

void FixedText::assign(std::string_view text) noexcept
{
    size_ = std::min(text.size(), kCapacity);
    std::memcpy(text_.data(), text.data(), size_);
    text_[size_] = '\0';
}

void FixedText::format(const char* format, ...) noexcept
{
    va_list args;
    va_start(args, format);
    const int written = std::vsnprintf(text_.data(), text_.size(), format, args);
    va_end(args);
    size_ = written < 0 ? 0 : std::min(static_cast<std::size_t>(written), kCapacity);
}

Publisher::Publisher() : event_fd_(eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC))
{
    if (!event_fd_)
        throw systemError(errno, "publisher: eventfd");
}

Publisher::~Publisher() = default;

void Publisher::publish() noexcept
{
    PublishedFrame& slot = slots_[back_];
    const uint64_t sequence = published_.load(std::memory_order_relaxed) + 1;
    slot.sequence = sequence;
    slot.published_ns = monotonicNowNs();
    slot.realtime_offset_ns = realtimeOffsetNs();
    const uint8_t previous =
        middle_.exchange(static_cast<uint8_t>(back_ | kFresh), std::memory_order_acq_rel);
    back_ = previous & kIndexMask;
    published_.store(sequence, std::memory_order_release);
    // The counter only wakes epoll; EAGAIN (counter at its maximum, reader far behind)
    // loses nothing, the reader takes the newest slot whatever the count.
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = ::write(event_fd_.get(), &one, sizeof one);
}

const PublishedFrame* Publisher::latest() noexcept
{
    if ((middle_.load(std::memory_order_relaxed) & kFresh) != 0) {
        const uint8_t previous = middle_.exchange(front_, std::memory_order_acq_rel);
        front_ = previous & kIndexMask;
    }
    const PublishedFrame& slot = slots_[front_];
    return slot.sequence == 0 ? nullptr : &slot;
}

void Publisher::wantRawUntil(int64_t deadline_ns) noexcept
{
    int64_t current = raw_wanted_until_ns_.load(std::memory_order_relaxed);
    while (current < deadline_ns && !raw_wanted_until_ns_.compare_exchange_weak(
                                        current, deadline_ns, std::memory_order_relaxed)) {
    }
}

void Publisher::clearEvent() noexcept
{
    uint64_t count = 0;
    [[maybe_unused]] const ssize_t got = ::read(event_fd_.get(), &count, sizeof count);
}

} // namespace stereod
