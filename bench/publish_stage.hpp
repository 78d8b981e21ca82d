#pragma once
// The publish stage as the daemon's worker runs it after process(): the worker processes
// straight into the publisher's write slot (so no result is copied), then the depth map is
// converted to uint16 millimetres in that slot (the form depth frames travel in) and
// Publisher::publish() does the triple-buffer swap and the eventfd write that wakes the
// I/O thread.
//
// Thread-bound: the thread that calls writeResult() and run() is the publisher's writer.

#include "daemon/publisher.hpp"
#include "pipeline/stereo_processor.hpp"

namespace stereod::bench {

class PublishStage {
  public:
    // Throws std::system_error when the publisher cannot be made (no eventfd).
    PublishStage() = default;

    // Where the worker processes the next frame: the result of the write slot. With no
    // reader taking results, the writer alternates between two of the three slots, so
    // three frames processed and published size every buffer the writer will use.
    DepthResult& writeResult() noexcept { return publisher_.writeSlot().result; }

    // Converts the write slot's depth to millimetres and publishes the slot.
    void run();

    // What run() does, for the benchmark's context.
    static const char* description();

  private:
    Publisher publisher_;
};

} // namespace stereod::bench
