#include "capture/frame_source.hpp"

namespace stereod {

const char* toString(SourceState state) noexcept
{
    return kSourceStates.name(state, "unknown");
}

} // namespace stereod
