#pragma once
// How the nearest object is read off a depth map.

#include "model/region_of_interest.hpp"

namespace stereod {

struct NearestSettings {
    RegionOfInterest roi;
    double min_depth_m = 0.1; // depths outside [min, max] are ignored
    double max_depth_m = 20.0;
    // The distance reported is this percentile of the in-range depths in the region:
    // a robust "nearest" that a few wrong pixels cannot move.
    double percentile = 5.0;
    // Below this fraction of valid pixels in the region, there is no reading.
    double min_valid_fraction = 0.10;
    // At least this many in-range pixels are needed for a reading.
    int min_pixels = 50;
    // ... and at least this fraction of the region: a sliver of in-range depths in a region
    // that is otherwise empty is more likely wrong matches (swapped cameras, a blind
    // camera seeing noise) than an obstacle.
    double min_in_range_fraction = 0.05;
    // Pixels whose match confidence (0..255, see MatchOutput) is below this are left out
    // of the statistic, as if they had no depth. 0 keeps every reported pixel.
    int min_confidence = 0;
    // When at least this fraction of the region (and min_pixels pixels) has its best match
    // at the near end of the disparity range, something may be nearer than the range can
    // see: the reading is "nearer than <closest depth>", never a number from the edge.
    double range_limit_fraction = 0.02;
};

} // namespace stereod
