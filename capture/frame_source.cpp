#include "capture/frame_source.hpp"

namespace stereod {

const char* toString(SourceState state) noexcept
{
    switch (state) {
    case SourceState::Stopped:
        return "stopped";
    case SourceState::Starting:
        return "starting";
    case SourceState::Running:
        return "running";
    case SourceState::Stalled:
        return "stalled";
    case SourceState::Failed:
        return "failed";
    case SourceState::Finished:
        return "finished";
    }
    return "unknown";
}

} // namespace stereod
