#pragma once
// What the correspondence search is told to do. Units: pixels unless a name says else.

namespace stereod {

enum class MatcherKind {
    Bm,    // OpenCV StereoBM: area-based correlation (SAD over a block)
    Sgbm,  // OpenCV StereoSGBM: semi-global matching
};

enum class SgbmMode { Sgbm, ThreeWay, Hh, Hh4 };

struct MatcherSettings {
    MatcherKind kind = MatcherKind::Sgbm;
    SgbmMode sgbm_mode = SgbmMode::Sgbm;
    // Closest distance the robot must see; sets the disparity range:
    // d_max = focal_px * baseline_m / min_depth_m - doffs_px.
    double min_depth_m = 0.5;
    // 0: derived from min_depth_m (rounded up to a multiple of 16). Otherwise a fixed
    // number of disparities, a positive multiple of 16.
    int num_disparities = 0;
    // Upper bound on the derived range (cost grows linearly with it); a warning says so
    // when the cap keeps the configured min_depth_m out of sight.
    int max_num_disparities = 256;
    int min_disparity = 0;
    int block_size = 5;                // odd; BM needs >= 5
    int uniqueness_ratio = 10;         // percent margin of the best cost over the second
    int speckle_window_px = 100;       // largest speckle to remove, in pixels; 0 disables
    int speckle_range_px = 2;          // disparity variation within a connected component
    int lr_max_diff_px = 1;            // left-right consistency tolerance; < 0 disables
    int p1 = 0;                        // SGBM smoothness penalties; 0: 8*cn*bs^2
    int p2 = 0;                        //                           0: 32*cn*bs^2
    int pre_filter_cap = 31;
    int texture_threshold = 10;        // BM only: minimum texture in the block
};

} // namespace stereod
