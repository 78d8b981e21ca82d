#pragma once
// A frame as a camera of a rig hands it to the stereo sync, and the ring between them.

#include <cstdint>

#include "capture/frame.hpp"
#include "capture/spsc_ring.hpp"

namespace stereod {

// A frame from one camera of a rig. The frame carries stamp_ns (CLOCK_MONOTONIC: the
// kernel's stamp when the driver gives a monotonic one, else the dequeue time),
// source_stamp_ns (the driver's raw stamp, 0 when it has none) and sequence (per camera,
// increasing across reopens). Destroying the handle gives the buffer back.
struct CapturedFrame {
    FrameHandle frame;
    uint32_t camera_index = 0; // the index given to the camera's constructor
};

using CapturedRing = SpscRing<CapturedFrame>;

} // namespace stereod
