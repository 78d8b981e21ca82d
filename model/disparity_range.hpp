#pragma once
// The disparity range the matcher searches, as the pipeline chose it from the settings
// and the rectified geometry (pipeline/stereo_processor.hpp, chooseDisparityRange()), for
// logs and `status`.
//
// Plain values. Units: pixels unless a name says else.

namespace stereod {

struct DisparityRange {
    int min_disparity = 0;
    int num_disparities = 0; // multiple of 16: the full-resolution search
    // The nearest depth the matcher measures: with the extended range, twice the
    // disparities' (about half the full-resolution range's closest depth).
    double closest_depth_m = 0.0;
    bool capped = false; // true when max_num_disparities kept min_depth_m out of sight
    // The nearest depth the full-resolution search sees (closest_depth_m without the
    // extended range).
    double range_closest_depth_m = 0.0;
    bool extended = false;     // census-sgm's extended range is on
    int last_disparity_px = 0; // the largest disparity measured (extended included)
};

} // namespace stereod
