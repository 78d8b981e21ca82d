#include "pipeline/reading_verdict.hpp"

#include <algorithm>

namespace stereod {
namespace {

bool outweighs(uint32_t evidence_pixels, const ReadingFacts& facts)
{
    const RegionMeasurement& r = facts.region;
    return evidence_pixels > 0 && evidence_pixels >= facts.min_pixels &&
           static_cast<double>(evidence_pixels) >=
               facts.near_evidence_fraction * static_cast<double>(r.region_pixels);
}

Reading refused(Reading reading, NoReadingReason reason)
{
    reading.valid = false;
    reading.distance_m = 0.0;
    reading.reason = reason;
    return reading;
}

} // namespace

Reading judgeReading(const ReadingFacts& facts)
{
    Reading reading;
    reading.stamp_ns = facts.stamp_ns;
    reading.frame = facts.frame;
    reading.min_valid_fraction = facts.min_valid_fraction;
    reading.min_pixels = facts.min_pixels;
    reading.skew_ms = facts.skew_ms;
    reading.max_skew_ms = facts.max_skew_ms;
    reading.age_ms = facts.age_ms;
    reading.max_age_ms = facts.max_age_ms;
    reading.near_field_guard = facts.near_field.guard_active;
    reading.closest_m = facts.near_field.closest_m;
    const RegionMeasurement& region = facts.region;
    const bool processed = facts.pair == PairOutcome::Processed;
    if (processed) {
        const double total = std::max<double>(1.0, region.region_pixels);
        reading.region_pixels = region.region_pixels;
        reading.valid_fraction = region.valid_pixels / total;
        reading.in_range_fraction = region.in_range_pixels / total;
        reading.range_limit_fraction = region.nearer_than_range_pixels / total;
        reading.inferred_fraction = region.inferred_pixels / total;
        reading.calibration_suspect = facts.calibration_suspect;
        if (facts.calibration_suspect)
            reading.calibration_row_offset_px = facts.calibration_row_offset_px;
    }

    if (!facts.calibrated)
        return refused(reading, NoReadingReason::Uncalibrated);
    if (facts.source_down)
        return refused(reading, NoReadingReason::SourceDown);
    if (facts.pair == PairOutcome::None)
        return refused(reading, NoReadingReason::NoFrameYet);
    if (facts.age_ms > facts.max_age_ms)
        return refused(reading, NoReadingReason::Stale);
    if (!processed)
        return refused(reading, NoReadingReason::BadFrame);
    if (facts.skew_ms > facts.max_skew_ms)
        return refused(reading, NoReadingReason::OutOfSync);
    // What the region's data would say (a number, too few matches, nothing in range, nearer
    // than the range) follows from comparing the wrong rows when the calibration failed.
    if (facts.calibration_failed && facts.withhold_when_failed)
        return refused(reading, NoReadingReason::CalibrationSuspect);

    if (outweighs(region.nearer_than_extended_pixels, facts)) {
        reading.nearer_than_m = facts.near_field.closest_m;
        return refused(reading, NoReadingReason::NearerThanRange);
    }
    if (outweighs(region.nearer_than_range_pixels, facts)) {
        reading.nearer_than_m = facts.near_field.range_closest_m;
        return refused(reading, NoReadingReason::NearerThanRange);
    }
    if (reading.valid_fraction < facts.min_valid_fraction || region.valid_pixels == 0)
        return refused(reading, NoReadingReason::TooFewValidPixels);
    if (region.in_range_pixels < facts.min_pixels ||
        reading.in_range_fraction < facts.min_in_range_fraction)
        return refused(reading, NoReadingReason::NothingInRange);
    reading.valid = true;
    reading.reason = NoReadingReason::None;
    reading.distance_m = region.percentile_depth_m;
    // A caveat on the number: without one, there is nothing it would qualify.
    reading.out_of_view_fraction =
        region.out_of_view_pixels / std::max<double>(1.0, region.region_pixels);
    return reading;
}

} // namespace stereod
