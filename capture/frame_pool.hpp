#pragma once
// A fixed set of frame buffers allocated once at start-up. A source takes a frame with
// acquire(), fills it, and hands it on; the buffer comes back when the last handle goes.
//
// Thread-safety: acquire() and the recycling may run on any threads at once; neither
// takes a lock nor allocates (each buffer has an atomic in-use flag; the pool is small,
// so acquire() scans it).

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "capture/frame.hpp"

namespace stereod {

class FramePool final : public FrameRecycler {
  public:
    // `count` buffers of `size` and OpenCV `type` (CV_8UC1 for grayscale frames); with
    // `colour`, each frame also has a CV_8UC3 colour plane of that size (Frame::colour).
    FramePool(std::size_t count, cv::Size size, int type = CV_8UC1, bool colour = false);
    ~FramePool() override;

    FramePool(const FramePool&) = delete;
    FramePool& operator=(const FramePool&) = delete;

    // A free frame with its metadata cleared, or an empty handle when every buffer is
    // in use (the caller counts that as a dropped frame).
    FrameHandle acquire() noexcept;

    void recycle(Frame* frame) noexcept override;

    std::size_t capacity() const noexcept { return frames_.size(); }
    std::size_t inUse() const noexcept;
    cv::Size frameSize() const noexcept { return size_; }
    bool hasColour() const noexcept { return !frames_.empty() && !frames_[0].colour.empty(); }
    // How many acquire() calls found every buffer taken.
    uint64_t exhausted() const noexcept { return exhausted_.load(std::memory_order_relaxed); }

  private:
    cv::Size size_;
    std::vector<Frame> frames_;
    std::unique_ptr<std::atomic<bool>[]> in_use_;
    std::atomic<uint64_t> exhausted_{0};
};

} // namespace stereod
