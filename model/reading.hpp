#pragma once
// The nearest-object reading the service hands to a robot: a distance, or "no reading"
// with the reason. Never a number the data do not support. Made by the pipeline
// (pipeline/reading_verdict.hpp), written by the protocol, printed by stereoctl.
//
// Plain values; the functions are pure (any thread). Units in the field names.

#include <cstdint>

#include "base/name_table.hpp"

namespace stereod {

enum class NoReadingReason {
    None,               // the reading is valid
    NoFrameYet,         // the service has not produced a result since it started
    TooFewValidPixels,  // valid_fraction below the configured minimum in the region
    NothingInRange,     // valid pixels exist, but none within [min_depth_m, max_depth_m]
    OutOfSync,          // the pair's capture times differ by more than allowed
    SourceDown,         // the frame source failed, stalled or finished
    BadFrame,           // the pair could not be processed (size mismatch, corrupt data)
    NearerThanRange,    // much of the region matches at the near end of the disparity range:
                        // something is nearer than the service can measure (nearer_than_m)
    CalibrationSuspect, // the calibration no longer rectifies the rig (calibration health
                        // failed) and the service is configured to withhold readings then
    Stale,              // the latest reading is older than the caller allows
    Uncalibrated,       // the service runs without a calibration (raw frames only)
};

// The stable machine codes of the protocol, one table for naming and parsing them.
inline constexpr NameTable<NoReadingReason, 11> kReasonCodes{{{
    {NoReadingReason::None, "none"},
    {NoReadingReason::NoFrameYet, "no_frame_yet"},
    {NoReadingReason::TooFewValidPixels, "too_few_valid_pixels"},
    {NoReadingReason::NothingInRange, "nothing_in_range"},
    {NoReadingReason::OutOfSync, "out_of_sync"},
    {NoReadingReason::SourceDown, "source_down"},
    {NoReadingReason::BadFrame, "bad_frame"},
    {NoReadingReason::NearerThanRange, "nearer_than_range"},
    {NoReadingReason::CalibrationSuspect, "calibration_suspect"},
    {NoReadingReason::Stale, "stale"},
    {NoReadingReason::Uncalibrated, "uncalibrated"},
}}};
static_assert(kReasonCodes.wellFormed());

// Stable machine code for the protocol ("too_few_valid_pixels", ...).
const char* reasonCode(NoReadingReason reason) noexcept;
// One human sentence, without numbers ("too few valid pixels in the region").
const char* reasonText(NoReadingReason reason) noexcept;
// True when the reason means the service is not producing (stale, source down, no frame
// yet), as opposed to "the data of a fresh frame did not support a number".
bool meansNotProducing(NoReadingReason reason) noexcept;

struct Reading {
    bool valid = false;
    double distance_m = 0.0; // meaningful only when valid
    NoReadingReason reason = NoReadingReason::NoFrameYet;
    int64_t stamp_ns = 0;            // capture time of the pair, CLOCK_MONOTONIC
    uint64_t frame = 0;              // pair index from the source
    double valid_fraction = 0.0;     // of the region's pixels, those with a valid depth
    double in_range_fraction = 0.0;  // of the region's pixels, those within the depth range
    double min_valid_fraction = 0.0; // the threshold in force, to explain a refusal
    uint32_t min_pixels = 0;         // in-range pixels needed, to explain a refusal
    uint32_t region_pixels = 0;      // size of the region of interest in pixels
    // Of the region's pixels, those that are near-field evidence: something there may be
    // nearer than the disparity range sees (pipeline/reading_verdict.hpp).
    double range_limit_fraction = 0.0;
    // Of the region's pixels, those without a measured depth whose nearest possible depth
    // other evidence gives (hidden from the right camera behind a nearer surface, or
    // matched at the coarse level only), counted in the distance when that brings it
    // nearer (pipeline/nearest_object.hpp).
    double inferred_fraction = 0.0;
    // Of the region's pixels, those in columns that cannot see as near as distance_m: the
    // image's left edge cuts their view (pipeline/nearest_object.hpp, LeftEdgeView), so a
    // surface that near there would go unseen. 0 when the whole region sees that near, and
    // without a distance.
    double out_of_view_fraction = 0.0;
    // NearerThanRange: the closest depth the disparity range can see, in metres; the
    // obstacle is nearer than this.
    double nearer_than_m = 0.0;
    // The closest depth the matcher measures (with census-sgm's extended range, half the
    // full-resolution range's), metres; 0 when no processor stands behind the reading.
    double closest_m = 0.0;
    // Whether the matcher looks for near-field evidence (census-sgm); OpenCV's matchers
    // cannot, and a surface nearer than their range may read as the background behind it.
    bool near_field_guard = false;
    // OutOfSync: the pair's frames apart and the most allowed; Stale: the reading's age
    // when asked and the most allowed, ms.
    double skew_ms = 0.0;
    double max_skew_ms = 0.0;
    double age_ms = 0.0;
    double max_age_ms = 0.0;
    // Set while calibration health is degraded or failed: the rows of matching points
    // are up to calibration_row_offset_px apart (the fitted model's largest row error over
    // the matches' area, signed right - left), so depth may be off.
    bool calibration_suspect = false;
    double calibration_row_offset_px = 0.0;
};

} // namespace stereod
