#include "bench/publish_stage.hpp"

#include "pipeline/depth_io.hpp"

namespace stereod::bench {

void PublishStage::run()
{
    PublishedFrame& slot = publisher_.writeSlot();
    depthToMillimetres(slot.result.depth_m, slot.depth_mm);
    publisher_.publish();
}

const char* PublishStage::description()
{
    return "process() straight into the publisher's write slot, then depthToMillimetres() "
           "in that slot and Publisher::publish() (triple-buffer swap, eventfd write), as "
           "the daemon's worker does";
}

} // namespace stereod::bench
