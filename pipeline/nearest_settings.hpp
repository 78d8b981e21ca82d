#pragma once
// How the nearest object is read off a depth map.

namespace stereod {

// A rectangle in fractions of the rectified left image (0..1), so that it survives a
// change of resolution. x/y are the top-left corner.
struct RegionOfInterest {
    double x = 0.25;
    double y = 0.25;
    double width = 0.5;
    double height = 0.5;
};

struct NearestSettings {
    RegionOfInterest roi;
    double min_depth_m = 0.1;          // depths outside [min, max] are ignored
    double max_depth_m = 20.0;
    // The distance reported is this percentile of the in-range depths in the region:
    // a robust "nearest" that a few wrong pixels cannot move.
    double percentile = 5.0;
    // Below this fraction of valid pixels in the region, there is no reading.
    double min_valid_fraction = 0.10;
    // At least this many in-range pixels are needed for a reading.
    int min_pixels = 50;
};

} // namespace stereod
