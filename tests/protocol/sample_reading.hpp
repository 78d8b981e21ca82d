#pragma once
// A valid reading with every field set, for the tests of what the protocol writes.

#include "model/reading.hpp"

namespace stereod {

inline Reading sampleValidReading()
{
    Reading reading;
    reading.valid = true;
    reading.reason = NoReadingReason::None;
    reading.distance_m = 1.41249;
    reading.stamp_ns = 81'263'511'234;
    reading.frame = 118;
    reading.valid_fraction = 0.83;
    reading.in_range_fraction = 0.8;
    reading.min_valid_fraction = 0.1;
    reading.region_pixels = 355680;
    return reading;
}

} // namespace stereod
