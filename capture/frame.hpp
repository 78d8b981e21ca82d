#pragma once
// Frames and the handles that carry them from a source to the worker.
//
// Ownership rule (for the whole project): std::unique_ptr hands ownership over, a
// reference or raw pointer only borrows for the duration of the call, std::shared_ptr
// goes by value.

#include <cstdint>
#include <limits>
#include <memory>

#include <opencv2/core/mat.hpp>

#include "base/clock.hpp"

namespace stereod {

struct Frame;

// Takes a frame back when its last holder lets go: a pool puts the buffer on its free
// list, a V4L2 camera queues the kernel buffer again (QBUF). Implementations must be
// callable from any thread and must not block.
class FrameRecycler {
  public:
    virtual ~FrameRecycler() = default;
    virtual void recycle(Frame* frame) noexcept = 0;
};

// One grayscale image from one camera, and the camera's colour beside it when the source
// keeps it. The pixels belong to the recycler that handed the frame out; a Frame is never
// copied, it travels as a FrameHandle.
struct Frame {
    cv::Mat image; // CV_8UC1, header over a buffer owned by `owner`
    // The same picture in colour: CV_8UC3, BGR (OpenCV's order), same size, a header over a
    // buffer owned by `owner`; empty for grey cameras and sources that keep no colour.
    cv::Mat colour;
    int64_t stamp_ns = 0;        // capture time on CLOCK_MONOTONIC
    int64_t source_stamp_ns = 0; // the source's own stamp (recorded stamp on replay)
    uint64_t sequence = 0;       // per-camera sequence number from the source
    FrameRecycler* owner = nullptr;
};

struct FrameReturn {
    void operator()(Frame* frame) const noexcept
    {
        if (frame != nullptr && frame->owner != nullptr)
            frame->owner->recycle(frame);
    }
};

// Owning handle: destroying it gives the buffer back to where it came from.
using FrameHandle = std::unique_ptr<Frame, FrameReturn>;

// A left and a right frame taken at (nearly) the same instant.
struct StereoPair {
    FrameHandle left;
    FrameHandle right;
    uint64_t index = 0; // pair number from the source, starting at 0

    // Capture time of the pair: the left frame's stamp (the reference camera).
    int64_t stampNs() const noexcept { return left ? left->stamp_ns : 0; }
    // Right minus left capture time, in ns (saturated, never wrapped).
    int64_t skewNs() const noexcept
    {
        return (left && right) ? saturatingSubNs(right->stamp_ns, left->stamp_ns) : 0;
    }
};

} // namespace stereod
