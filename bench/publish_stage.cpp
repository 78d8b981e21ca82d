#include "bench/publish_stage.hpp"

#include "pipeline/depth_io.hpp"

namespace stereod::bench {

PublishStage::PublishStage(const DepthResult& sample)
{
    // With no reader taking results, the writer alternates between two of the three slots;
    // three rounds fill them whatever slot it starts with.
    for (int round = 0; round < 3; ++round) {
        DepthResult& result = publisher_.writeSlot().result;
        result = sample;
        // Own buffers per slot, as the worker's results have.
        result.left_rectified = sample.left_rectified.clone();
        result.disparity = sample.disparity.clone();
        result.depth_m = sample.depth_m.clone();
        run();
    }
}

void PublishStage::run()
{
    PublishedFrame& slot = publisher_.writeSlot();
    depthToMillimetres(slot.result.depth_m, slot.depth_mm);
    publisher_.publish();
}

const char* PublishStage::description()
{
    return "depthToMillimetres() into the publisher's write slot, then Publisher::publish() "
           "(triple-buffer swap, eventfd write), as the daemon's worker does after process()";
}

} // namespace stereod::bench
