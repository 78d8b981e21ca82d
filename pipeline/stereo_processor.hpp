#pragma once
// The stereo chain for one pair: rectify -> match -> depth -> nearest object -> point
// cloud. No sockets, no threads of its own (the matcher's bands aside, rows are shared out
// over OpenCV's pool: row_stripes.hpp), no knowledge of where frames come from: the
// service's worker, `stereoctl depth` and the benchmarks all run this same code.
//
// Thread-bound: one StereoProcessor per worker thread. All buffers are allocated in the
// constructor (or on the first frame of a size); process() allocates nothing in steady
// state.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "model/cloud_point.hpp"
#include "model/reading.hpp"
#include "model/stage_timings.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/matcher_settings.hpp"
#include "pipeline/nearest_object.hpp"
#include "pipeline/nearest_settings.hpp"
#include "pipeline/reading_verdict.hpp"

namespace stereod {

// What the outputs keep: the depth image and the point cloud (and so every snapshot,
// subscription, bag and live view channel that carries them). The reading and the zones
// are made before the outputs are cut: the cap changes no reading.
struct OutputSettings {
    // Depths beyond this (metres) are left out of the outputs: at such depths one pixel
    // of disparity is worth a large share of the depth, and a depth of hundreds of metres
    // from a fraction of a pixel is noise, not a measurement. nullopt ("auto"):
    // defaultMaxOutputDepth() of the calibration.
    std::optional<double> max_depth_m;
};

// Beyond the depth where one pixel of disparity changes the depth by this share, the
// depth says little more than "far": the default cap of the outputs.
inline constexpr double kMaxOutputDepthStepShare = 0.25;

// The default cap: the depth where one pixel of disparity is kMaxOutputDepthStepShare of
// it, f·B·share / 1 px (where d + doffs = 1 px / share), in metres.
double defaultMaxOutputDepth(const RectifiedGeometry& geometry);

struct ProcessorSettings {
    MatcherSettings matcher;
    NearestSettings nearest;
    OutputSettings output;
    bool compute_cloud = true; // the point cloud is skipped when nobody needs it
};

// Everything the chain produced for one pair. Reused frame after frame: buffers keep
// their capacity.
struct DepthResult {
    cv::Mat left_rectified; // CV_8UC1, what the matcher saw
    // The left camera's colour rectified with the same maps: CV_8UC3, BGR (OpenCV's
    // order); empty when the left input is grey.
    cv::Mat left_rectified_colour;
    cv::Mat disparity;             // CV_32FC1, pixels; invalid = +inf (Middlebury)
    cv::Mat confidence;            // CV_8UC1, 0 invalid, 1..255 (see MatchOutput)
    cv::Mat near_field;            // CV_8UC1, near-field evidence (MatchOutput::near_field)
    cv::Mat depth_m;               // CV_32FC1, metres; invalid (or beyond the cap) = 0
    std::vector<CloudPoint> cloud; // valid depths within the cap; capacity kept across frames
    // One colour per cloud point, in the same order; empty when the left input is grey.
    std::vector<CloudColour> cloud_colour;
    // What the pair's reading is judged from (the worker adds skew and calibration health,
    // the socket server the source and the age), and the verdict on what the chain knew.
    ReadingFacts facts;
    Reading reading;
    StageTimings timings;
    uint64_t frame = 0;
    int64_t stamp_ns = 0; // capture time of the pair, CLOCK_MONOTONIC
};

// Works out the disparity range from the settings and the rectified geometry: the
// full-resolution search, and what census-sgm's extended range adds.
DisparityRange chooseDisparityRange(const MatcherSettings& settings,
                                    const RectifiedGeometry& geometry);

// Checks the settings against each other and against the rectified geometry, exactly as
// the constructor and updateSettings() do (disparity range within the image width, block
// size within the image, a region of interest of at least one pixel); returns the
// disparity range they give. Throws SettingsError (base/settings_error.hpp) naming the field
// of ProcessorSettings at fault ("matcher.num_disparities").
DisparityRange validateProcessorSettings(const ProcessorSettings& settings,
                                         const RectifiedGeometry& geometry);

class StereoProcessor {
  public:
    // Computes the rectification maps (fixed-point) once and sets up the matcher.
    // Throws CalibrationError / std::invalid_argument with the reason when the settings
    // and calibration cannot work together.
    StereoProcessor(const StereoCalibration& calibration, const ProcessorSettings& settings);
    ~StereoProcessor();

    StereoProcessor(const StereoProcessor&) = delete;
    StereoProcessor& operator=(const StereoProcessor&) = delete;

    // Runs the chain on one raw (unrectified) pair, 8-bit grey or colour (BGR, BGRA): the
    // matcher works on grey; a colour left is also rectified into
    // out.left_rectified_colour and colours the cloud. Frames whose size does not
    // match the calibration give a BadFrame reading, never an exception. out.facts holds
    // the pair's facts, out.reading judgeReading() of them, both from the whole depth; then
    // depths beyond maxOutputDepth() are cleared from out.depth_m, and the cloud is made
    // from what is left.
    void process(const cv::Mat& left, const cv::Mat& right, int64_t stamp_ns, uint64_t frame,
                 DepthResult& out);
    // The same with the left camera's colour beside its grey image, for sources that
    // decode both (the matcher then sees the camera's own luma, as with a grey source):
    // `left_colour` is CV_8UC3 (BGR) of the left image's size, or empty for none.
    void process(const cv::Mat& left, const cv::Mat& left_colour, const cv::Mat& right,
                 int64_t stamp_ns, uint64_t frame, DepthResult& out);

    // Applies settings that can change live (matcher parameters, nearest settings).
    // Throws std::invalid_argument, leaving the current settings in force, if invalid.
    void updateSettings(const ProcessorSettings& settings);

    // The right image of the last pair as it was matched (rectified): the processor's own
    // buffer, or with a rectified-only calibration a view of the input, so valid only
    // while that input is. Empty before the first pair and after a bad one.
    const cv::Mat& lastRightRectified() const;

    const StereoCalibration& calibration() const;
    const ProcessorSettings& settings() const;
    DisparityRange disparityRange() const;
    // What the nearest-object region sees near the image's left edge, with this range.
    LeftEdgeView regionLeftEdge() const;
    // The outputs' depth cap in force (output.max_depth_m, or its default), metres.
    double maxOutputDepth() const;
    // A name for logs and status: "census-sgm", "sgbm", "sgbm-3way", "bm".
    std::string matcherName() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace stereod
