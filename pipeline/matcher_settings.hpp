#pragma once
// What the correspondence search is told to do. Units: pixels unless a name says else.

#include <array>
#include <optional>
#include <string_view>

#include "base/name_table.hpp"
#include "model/disparity_range.hpp"

namespace stereod {

enum class MatcherKind {
    CensusSgm, // ours: census transform + semi-global matching on SIMD (pipeline/sgm)
    Bm,        // OpenCV StereoBM: area-based correlation (SAD over a block), a reference
    Sgbm,      // OpenCV StereoSGBM: semi-global matching, a reference
};

enum class SgbmMode { Sgbm, ThreeWay, Hh, Hh4 };

// The matcher's name (matcher.algorithm, stereoctl depth --matcher, status) sets two
// fields: the matcher and, for OpenCV's SGBM, its mode.
struct MatcherAlgorithm {
    std::string_view name;
    MatcherKind kind;
    SgbmMode mode;
};

// The one table of the algorithms' names, in the order they are listed to users.
inline constexpr std::array<MatcherAlgorithm, 6> kMatcherAlgorithms{{
    {"census-sgm", MatcherKind::CensusSgm, SgbmMode::Sgbm},
    {"sgbm", MatcherKind::Sgbm, SgbmMode::Sgbm},
    {"sgbm-3way", MatcherKind::Sgbm, SgbmMode::ThreeWay},
    {"sgbm-hh", MatcherKind::Sgbm, SgbmMode::Hh},
    {"sgbm-hh4", MatcherKind::Sgbm, SgbmMode::Hh4},
    {"bm", MatcherKind::Bm, SgbmMode::Sgbm},
}};

// The algorithm of that name; none when no algorithm has it.
constexpr std::optional<MatcherAlgorithm> matcherAlgorithmNamed(std::string_view name)
{
    for (const MatcherAlgorithm& algorithm : kMatcherAlgorithms)
        if (algorithm.name == name)
            return algorithm;
    return std::nullopt;
}

// The name of the algorithm `kind` and `mode` select (the mode counts for SGBM only).
constexpr std::string_view matcherAlgorithmName(MatcherKind kind, SgbmMode mode)
{
    for (const MatcherAlgorithm& algorithm : kMatcherAlgorithms)
        if (algorithm.kind == kind && (kind != MatcherKind::Sgbm || algorithm.mode == mode))
            return algorithm.name;
    return "?";
}

// What census-sgm's automatic settings are tuned for.
enum class MatcherTuning {
    // Natural, textured scenes: tuned on the 17 real scenes of shared/data.
    Natural,
    // Man-made scenes of uniform planar surfaces and repeating patterns (walls, boxes,
    // boards, tiles): tuned on a real rig's chessboard (opencv-doc's 13 pairs).
    Planar,
    // Natural, and planar's steps only where a row runs through a pattern that repeats
    // along it (pipeline/sgm/periodic_pattern.hpp): for scenes that hold both.
    Patterns,
};

// The tunings' names (matcher.tuning, stereoctl's --tuning), one table for naming and
// parsing them.
inline constexpr NameTable<MatcherTuning, 3> kMatcherTunings{{{
    {MatcherTuning::Natural, "natural"},
    {MatcherTuning::Planar, "planar"},
    {MatcherTuning::Patterns, "patterns"},
}}};
static_assert(kMatcherTunings.wellFormed());

struct MatcherSettings {
    // Ours: on the real scenes of shared/data it reports half the wrong and too-far pixels
    // of OpenCV's SGBM in half the time (docs/configuration.md).
    MatcherKind kind = MatcherKind::CensusSgm;
    SgbmMode sgbm_mode = SgbmMode::Sgbm;
    // census-sgm: the scenes its unset settings' values suit.
    MatcherTuning tuning = MatcherTuning::Natural;
    // Closest distance the robot must see; sets the disparity range:
    // d_max = focal_px * baseline_m / min_depth_m - doffs_px.
    double min_depth_m = 0.5;
    // Every std::optional below is a setting the matcher decides when it is unset (the
    // configuration's `auto`, or the key left out): effectiveMatcherSettings()
    // (pipeline/matcher_defaults.hpp) is the one place that says what each becomes.
    //
    // Unset: derived from min_depth_m (rounded up to a multiple of 16). Otherwise a fixed
    // number of disparities, a positive multiple of 16.
    std::optional<int> num_disparities;
    // Upper bound on the derived range (cost grows linearly with it); a warning says so
    // when the cap keeps the configured min_depth_m out of sight.
    int max_num_disparities = 256;
    int min_disparity = 0;
    int block_size = 5; // OpenCV's matchers: odd; BM needs >= 5
    // The next four, every matcher has; unset, each matcher has its own.
    //
    // Percent margin of the best cost over the second.
    std::optional<int> uniqueness_ratio;
    // Largest speckle removed, in pixels (0 disables), and the disparity variation within
    // one connected component.
    std::optional<int> speckle_window_px;
    std::optional<int> speckle_range_px;
    // Left-right consistency tolerance; < 0 disables.
    std::optional<int> lr_max_diff_px;
    // Smoothness penalties: census-sgm counts them in census bits, OpenCV's SGBM in its own
    // cost units.
    std::optional<int> p1;
    std::optional<int> p2;
    int pre_filter_cap = 31;    // OpenCV's matchers only
    int texture_threshold = 10; // BM only: minimum texture in the block

    // census-sgm only.
    std::optional<int> census_width; // census window in pixels, odd
    std::optional<int> census_height;
    std::optional<int> paths; // aggregation paths, 3 or 5
    // P2 / (1 + |dI| / scale), grey levels; 0: no adaptation (`off`).
    std::optional<int> p2_gradient_scale;
    std::optional<int> threads; // threads inside matching
    // census-sgm: a half-resolution level over twice the disparity range, merged into the
    // full-resolution match (pipeline/sgm/pyramid_sgm.hpp): the closest depth measured
    // halves for about a quarter more matching time.
    bool extended_range = true;
    // census-sgm, with the extended range: the half-resolution level runs first and the
    // full resolution searches only around what it measured, the whole range where that
    // is unreliable (pipeline/sgm/guided_spans.hpp).
    bool guided_search = false;
    // With the guided search: the share of the full level's lanes above which a frame
    // searches the whole range instead (sgm::PyramidSgmSettings::guided_max_share); unset:
    // the pyramid's own. Not a configuration key: tests set it to measure the spans
    // whatever they search.
    std::optional<double> guided_max_share;
};

} // namespace stereod
