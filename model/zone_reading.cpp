#include "model/zone_reading.hpp"

namespace stereod {

const char* zoneStateName(ZoneState state) noexcept
{
    switch (state) {
    case ZoneState::Clear:
        return "clear";
    case ZoneState::Occupied:
        return "occupied";
    case ZoneState::Unknown:
        return "unknown";
    }
    return "unknown";
}

} // namespace stereod
