#include "capture/frame_pool.hpp"

#include <cassert>
#include <ctime>

namespace stereod {

FramePool::FramePool(std::size_t count, cv::Size size, int type, bool colour)
    : size_(size), frames_(count), in_use_(std::make_unique<std::atomic<bool>[]>(count))
{
    for (std::size_t i = 0; i < count; ++i) {
        frames_[i].image.create(size, type);
        if (colour)
            frames_[i].colour.create(size, CV_8UC3);
        frames_[i].owner = this;
        in_use_[i].store(false, std::memory_order_relaxed);
    }
}

FramePool::~FramePool()
{
    // Every handle must be gone before its pool: a frame outliving it would point at
    // freed memory.
    assert(inUse() == 0);
}

FrameHandle FramePool::acquire() noexcept
{
    for (std::size_t i = 0; i < frames_.size(); ++i) {
        bool expected = false;
        if (in_use_[i].compare_exchange_strong(expected, true, std::memory_order_acquire)) {
            Frame& frame = frames_[i];
            frame.stamp_ns = 0;
            frame.source_stamp_ns = 0;
            frame.sequence = 0;
            return FrameHandle(&frame);
        }
    }
    exhausted_.fetch_add(1, std::memory_order_relaxed);
    return FrameHandle();
}

void FramePool::recycle(Frame* frame) noexcept
{
    const auto index = static_cast<std::size_t>(frame - frames_.data());
    assert(index < frames_.size());
    in_use_[index].store(false, std::memory_order_release);
}

std::size_t FramePool::inUse() const noexcept
{
    std::size_t n = 0;
    for (std::size_t i = 0; i < frames_.size(); ++i)
        n += in_use_[i].load(std::memory_order_relaxed) ? 1 : 0;
    return n;
}

} // namespace stereod
