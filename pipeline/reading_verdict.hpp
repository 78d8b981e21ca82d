#pragma once
// The verdict of a reading: whether a pair's nearest-object distance may be given as a
// number, or which reason says why not. One pure function over the facts, with the
// precedence written once (judgeReading()); the stereo chain, the worker and the socket
// server each gather the facts they know and call it, and none of them decides on its
// own. Tested as a table (tests/pipeline/reading_verdict_test.cpp).
//
// Reentrant: pure functions.

#include <cstdint>

#include "model/reading.hpp"

namespace stereod {

// What the region of a depth map holds (NearestObjectFinder::measure()).
struct RegionMeasurement {
    uint32_t region_pixels = 0;
    uint32_t valid_pixels = 0;    // with a depth (and confidence enough)
    uint32_t in_range_pixels = 0; // of those, within [min_depth_m, max_depth_m]
    // Unmeasured pixels with an inferred nearest depth (NearestObjectFinder::measure()).
    uint32_t inferred_pixels = 0;
    // The configured percentile of the in-range depths, or of those with the inferred
    // pixels' bounds when that is nearer, metres; 0 when none is in range.
    double percentile_depth_m = 0.0;
    // Near-field evidence (the matcher's near_field plane): pixels that may show a surface
    // nearer than the full-resolution range (any level of evidence), and of those, nearer
    // than the extended range too.
    uint32_t nearer_than_range_pixels = 0;
    uint32_t nearer_than_extended_pixels = 0;
    // Pixels of the columns that cannot see as near as percentile_depth_m (the image's left
    // edge cuts their view; filled by the stereo chain, which knows the geometry).
    uint32_t out_of_view_pixels = 0;
};

// When the region's evidence of something nearer than the range outweighs a number: at
// least range_limit_fraction of the region and min_pixels pixels (NearestSettings).
struct NearFieldFacts {
    // The matcher looks for the evidence (census-sgm); OpenCV's matchers cannot, and their
    // readings say the guard is not active.
    bool guard_active = false;
    // The closest depth the full-resolution range sees, and the closest the matcher
    // measures (the extended range's; the same without it), metres.
    double range_closest_m = 0.0;
    double closest_m = 0.0;
};

// The outcome of a pair before its region was measured.
enum class PairOutcome {
    None,      // no pair yet
    Processed, // through the chain: the region measurement holds
    BadFrame,  // not processed (missing frame, wrong size, corrupt data, an error)
};

// Everything a verdict depends on. Each party fills what it knows; the rest keeps the
// defaults, which judge nothing (a fresh, calibrated, healthy, in-sync pair).
struct ReadingFacts {
    bool calibrated = true;
    bool source_down = false;
    PairOutcome pair = PairOutcome::None;
    int64_t stamp_ns = 0; // capture time of the pair, CLOCK_MONOTONIC
    uint64_t frame = 0;
    // Capture times of the pair's two frames apart, and the most allowed, ms.
    double skew_ms = 0.0;
    double max_skew_ms = 1e300;
    // The region and the thresholds it is judged by (NearestSettings).
    RegionMeasurement region;
    double min_valid_fraction = 0.0;
    uint32_t min_pixels = 1;
    double min_in_range_fraction = 0.0;
    double near_evidence_fraction = 0.02; // NearestSettings::range_limit_fraction
    NearFieldFacts near_field;
    // Calibration health: degraded or failed (readings flagged), failed, and whether the
    // configuration withholds readings then.
    bool calibration_suspect = false;
    bool calibration_failed = false;
    bool withhold_when_failed = false;
    double calibration_row_offset_px = 0.0;
    // Age of the pair when asked, and the most the caller allows, ms (none: not judged).
    double age_ms = 0.0;
    double max_age_ms = 1e300;
};

// The reading for these facts. Precedence, first match wins:
//  1. uncalibrated; 2. source down; 3. no pair yet; 4. stale (older than allowed);
//  5. bad frame; 6. out of sync;
//  7. calibration failed, readings withheld (over a number and over what the region's
//     data said: those follow from comparing the wrong rows);
//  8. nearer than the range: near-field evidence beyond the extended range (bound: its
//     closest depth), else beyond the full-resolution range that the extended range did
//     not measure (bound: the full range's closest depth). Either outweighs a number:
//     the evidence is of something the region's depths do not hold;
//  9. too few valid pixels; 10. nothing in range;
//  11. valid: the percentile depth.
// calibration_suspect is carried on every reading of a processed pair while the health is
// degraded or failed.
Reading judgeReading(const ReadingFacts& facts);

} // namespace stereod
