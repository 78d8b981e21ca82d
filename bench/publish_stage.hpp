#pragma once
// The publish stage as the daemon's worker runs it after process(): the depth map
// converted to uint16 millimetres in the publisher's write slot (the form depth frames
// travel in), then Publisher::publish(), the triple-buffer swap and the eventfd write that
// wakes the I/O thread. The worker processes straight into the write slot, so no result
// is copied on the way.
//
// Thread-bound: the thread that calls run() is the publisher's writer.

#include "daemon/publisher.hpp"
#include "pipeline/stereo_processor.hpp"

namespace stereod::bench {

class PublishStage {
  public:
    // Puts a copy of `sample` into every slot the writer gets, as if the worker had
    // processed into it, and publishes each once, so that the slots' buffers are sized
    // before anything is timed. Throws std::system_error when the publisher cannot be made.
    explicit PublishStage(const DepthResult& sample);

    // Publishes the result in the write slot.
    void run();

    // What run() does, for the benchmark's context and label.
    static const char* description();

  private:
    Publisher publisher_;
};

} // namespace stereod::bench
