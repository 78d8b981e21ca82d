#include "model/zone_reading.hpp"

namespace stereod {

const char* zoneStateName(ZoneState state) noexcept
{
    return kZoneStates.name(state, "unknown");
}

} // namespace stereod
