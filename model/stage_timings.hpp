#pragma once
// Where a pair's processing time went, stage by stage: filled by the stereo chain
// (pipeline/stereo_processor.hpp), averaged by the worker, reported in `status`.
//
// Plain values. Units: milliseconds.

namespace stereod {

// Milliseconds spent in each stage of one StereoProcessor::process() call.
struct StageTimings {
    double rectify_ms = 0.0;
    double match_ms = 0.0;
    double depth_ms = 0.0;
    double nearest_ms = 0.0;
    double cloud_ms = 0.0;
    // Parts of match_ms: census-sgm's extended range and near-field probe.
    double extended_range_ms = 0.0;
    double near_field_probe_ms = 0.0;
    double colour_ms = 0.0;       // the colour left rectified; exactly 0 for grey input
    double cloud_colour_ms = 0.0; // the cloud's colours; exactly 0 without them
    double totalMs() const
    {
        return rectify_ms + colour_ms + match_ms + depth_ms + nearest_ms + cloud_ms +
               cloud_colour_ms;
    }
};

} // namespace stereod
