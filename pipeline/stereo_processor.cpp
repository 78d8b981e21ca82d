#include "pipeline/stereo_processor.hpp"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <opencv2/imgproc.hpp>
#include <spdlog/spdlog.h>

#include "base/settings_error.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/hidden_surfaces.hpp"
#include "pipeline/matcher.hpp"
#include "pipeline/nearest_object.hpp"
#include "pipeline/rectifier.hpp"
#include "pipeline/row_stripes.hpp"
#include "pipeline/triangulation.hpp"

namespace stereod {
namespace {

// In the rows and columns of `area`: `into` takes the larger (nearer) of its disparity and
// `from`'s where `from` has one (+inf: none).
void nearerOf(const cv::Mat& from, const cv::Rect& area, cv::Mat& into)
{
    for (int y = area.y; y < area.y + area.height; ++y) {
        const float* f = from.ptr<float>(y);
        float* t = into.ptr<float>(y);
        for (int x = area.x; x < area.x + area.width; ++x) {
            const bool into_nearer = std::isfinite(t[x]) && t[x] >= f[x];
            t[x] = std::isfinite(f[x]) && !into_nearer ? f[x] : t[x];
        }
    }
}

using Clock = std::chrono::steady_clock;

constexpr int kDisparityStep = 16; // OpenCV's matchers search multiples of 16

double msBetween(Clock::time_point a, Clock::time_point b)
{
    return std::chrono::duration<double, std::milli>(b - a).count();
}

std::string describeSize(cv::Size size)
{
    return std::to_string(size.width) + "x" + std::to_string(size.height);
}

void warnIfCapped(const DisparityRange& range, const MatcherSettings& settings)
{
    if (range.capped)
        spdlog::warn("disparity range capped at {} by max_num_disparities: the closest "
                     "depth in sight is {:.3f} m, not min_depth_m {:.3f} m",
                     range.num_disparities, range.closest_depth_m, settings.min_depth_m);
}

} // namespace

DisparityRange chooseDisparityRange(const MatcherSettings& settings,
                                    const RectifiedGeometry& geometry)
{
    DisparityRange range;
    range.min_disparity = settings.min_disparity;
    if (settings.num_disparities) {
        range.num_disparities = *settings.num_disparities;
    } else {
        // Disparities min_disparity .. min_disparity + n - 1 are searched: n must reach
        // the disparity of the closest depth, d_max = f*B/Z_min - doffs.
        const double d_max = geometry.disparityAtDepth(settings.min_depth_m);
        const double needed = std::ceil(d_max) - settings.min_disparity + 1.0;
        const double cap = settings.max_num_disparities;
        if (!(needed <= cap)) {
            range.num_disparities = settings.max_num_disparities;
            range.capped = true;
        } else {
            const double steps = std::max(1.0, std::ceil(needed / kDisparityStep));
            range.num_disparities = static_cast<int>(steps) * kDisparityStep;
        }
    }
    const auto closest = [&](double largest) {
        return largest + geometry.doffs_px > 0.0 ? geometry.depthFromDisparity(largest)
                                                 : std::numeric_limits<double>::infinity();
    };
    const int full_last = range.min_disparity + range.num_disparities - 1;
    range.extended = settings.kind == MatcherKind::CensusSgm && settings.extended_range;
    // The coarse level searches the same count of half-resolution disparities from half
    // the first one (pipeline/sgm/pyramid_sgm.hpp).
    const int coarse_first =
        range.min_disparity >= 0 ? range.min_disparity / 2 : -((-range.min_disparity + 1) / 2);
    range.last_disparity_px =
        range.extended ? 2 * (coarse_first + range.num_disparities - 1) : full_last;
    range.range_closest_depth_m = closest(full_last);
    range.closest_depth_m = closest(range.last_disparity_px);
    // The cap keeps min_depth_m out of sight only when the extended range does not reach it.
    if (range.capped && range.closest_depth_m <= settings.min_depth_m)
        range.capped = false;
    return range;
}

double defaultMaxOutputDepth(const RectifiedGeometry& geometry)
{
    return geometry.focal_px * geometry.baseline_m * kMaxOutputDepthStepShare;
}

DisparityRange validateProcessorSettings(const ProcessorSettings& settings,
                                         const RectifiedGeometry& geometry)
{
    try {
        validateMatcherSettings(settings.matcher);
    } catch (const SettingsError& e) {
        throw e.within("matcher");
    }
    try {
        validateNearestSettings(settings.nearest);
    } catch (const SettingsError& e) {
        throw e.within("nearest");
    }
    if (settings.output.max_depth_m && !(*settings.output.max_depth_m > 0.0))
        throw SettingsError("output.max_depth_m", std::to_string(*settings.output.max_depth_m) +
                                                      " m: must be auto or above 0 m");
    const DisparityRange range = chooseDisparityRange(settings.matcher, geometry);
    const cv::Size size = toCv(geometry.image_size);
    const int last_disparity = range.min_disparity + range.num_disparities - 1;
    if (last_disparity >= size.width) {
        // Name the key that set the range: the explicit count, or the cap it came from.
        const char* key = settings.matcher.num_disparities ? "matcher.num_disparities"
                          : range.capped                   ? "matcher.max_num_disparities"
                                                           : "matcher.min_depth_m";
        throw SettingsError(key, "a disparity range up to " + std::to_string(last_disparity) +
                                     " px (" + std::to_string(range.num_disparities) +
                                     " disparities from " + std::to_string(range.min_disparity) +
                                     ") leaves no column to match in an image " +
                                     std::to_string(size.width) + " px wide");
    }
    if (settings.matcher.block_size >= std::min(size.width, size.height))
        throw SettingsError("matcher.block_size", std::to_string(settings.matcher.block_size) +
                                                      " does not fit in a " + describeSize(size) +
                                                      " image");
    // A region that rounds to no pixel at all would read "0.0 % valid" on every frame.
    const cv::Rect region = regionPixels(settings.nearest.roi, size);
    if (region.area() == 0)
        throw SettingsError("nearest.roi", std::to_string(region.width) + "x" +
                                               std::to_string(region.height) + " px in a " +
                                               describeSize(size) +
                                               " image: the region must hold at least one pixel");
    return range;
}

struct StereoProcessor::Impl {
    Impl(const StereoCalibration& calibration_in, const ProcessorSettings& settings_in)
        : calibration(calibration_in), settings(settings_in),
          range(validateProcessorSettings(settings_in, calibration_in.rectified)),
          rectifier(calibration_in), matcher(makeMatcher(settings_in.matcher, range)),
          nearest(static_cast<size_t>(calibration_in.rectified.image_size.area())),
          max_output_depth_m(settings_in.output.max_depth_m.value_or(
              defaultMaxOutputDepth(calibration_in.rectified)))
    {
        if (rectifier.remaps())
            right_rectified.create(toCv(calibration.rectified.image_size), CV_8UC1);
        warnIfCapped(range, settings.matcher);
    }

    // A CV_8UC1 view of an input image of the calibrated size, converting colour into
    // `gray` (reused). Returns an empty Mat and sets `problem` when the image cannot be
    // used.
    cv::Mat grayView(const cv::Mat& image, cv::Mat& gray, const char* side,
                     std::string& problem) const
    {
        if (image.empty()) {
            problem = std::string(side) + " image is empty";
            return {};
        }
        if (image.depth() != CV_8U) {
            problem = std::string(side) + " image is not 8-bit";
            return {};
        }
        if (image.size() != toCv(calibration.rectified.image_size)) {
            problem = std::string(side) + " image is " + describeSize(image.size()) +
                      ", the calibration is for " +
                      describeSize(toCv(calibration.rectified.image_size));
            return {};
        }
        switch (image.channels()) {
        case 1:
            return image;
        case 3:
            cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
            return gray;
        case 4:
            cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
            return gray;
        default:
            problem =
                std::string(side) + " image has " + std::to_string(image.channels()) + " channels";
            return {};
        }
    }

    void badFrame(DepthResult& out, const std::string& problem)
    {
        if (!last_frame_bad)
            spdlog::warn("frame {}: {}; the pair gives no reading", out.frame, problem);
        last_frame_bad = true;
        // Leave nothing of the previous frame behind that could pass for this one.
        const cv::Size size = toCv(calibration.rectified.image_size);
        out.left_rectified.create(size, CV_8UC1);
        out.left_rectified.setTo(0);
        out.left_rectified_colour.release();
        out.cloud_colour.clear();
        out.disparity.create(size, CV_32FC1);
        out.disparity.setTo(std::numeric_limits<float>::infinity());
        out.confidence.create(size, CV_8UC1);
        out.confidence.setTo(0);
        out.near_field.create(size, CV_8UC1);
        out.near_field.setTo(0);
        out.depth_m.create(size, CV_32FC1);
        out.depth_m.setTo(0);
        out.cloud.clear();
        out.facts = ReadingFacts{};
        out.facts.pair = PairOutcome::BadFrame;
        out.facts.stamp_ns = out.stamp_ns;
        out.facts.frame = out.frame;
        out.facts.min_valid_fraction = settings.nearest.min_valid_fraction;
        out.facts.near_field = nearFieldFacts();
        out.reading = judgeReading(out.facts);
    }

    NearFieldFacts nearFieldFacts() const
    {
        return {matcher->nearFieldGuard(), range.range_closest_depth_m, range.closest_depth_m};
    }

    StereoCalibration calibration;
    ProcessorSettings settings;
    DisparityRange range;
    Rectifier rectifier;
    std::unique_ptr<Matcher> matcher;
    NearestObjectFinder nearest;
    PointCloudBuilder cloud;
    double max_output_depth_m;     // the outputs' depth cap in force, metres
    cv::Mat left_gray, right_gray; // colour inputs converted, reused
    cv::Mat left_bgr;              // a BGRA left without its alpha, reused
    cv::Mat right_rectified;       // full calibration only, reused
    cv::Mat last_right;            // what the matcher saw last (see lastRightRectified())
    cv::Mat coarse_only_px;        // MatchOutput::coarse_only_px, reused
    cv::Mat inferred_px;           // unmeasured pixels' nearest disparities, reused
    cv::Mat inferred_depth_m;      // ... as depths, in the region
    bool last_frame_bad = false;   // log a run of bad frames once
};

StereoProcessor::StereoProcessor(const StereoCalibration& calibration,
                                 const ProcessorSettings& settings)
{
    validateCalibration(calibration, "calibration");
    impl_ = std::make_unique<Impl>(calibration, settings);
}

StereoProcessor::~StereoProcessor() = default;

void StereoProcessor::process(const cv::Mat& left, const cv::Mat& right, int64_t stamp_ns,
                              uint64_t frame, DepthResult& out)
{
    process(left, cv::Mat(), right, stamp_ns, frame, out);
}

void StereoProcessor::process(const cv::Mat& left, const cv::Mat& left_colour, const cv::Mat& right,
                              int64_t stamp_ns, uint64_t frame, DepthResult& out)
{
    Impl& p = *impl_;
    out.frame = frame;
    out.stamp_ns = stamp_ns;
    out.timings = StageTimings{};

    const Clock::time_point t0 = Clock::now();
    std::string problem;
    const cv::Mat left_gray = p.grayView(left, p.left_gray, "left", problem);
    const cv::Mat right_gray =
        left_gray.empty() ? cv::Mat() : p.grayView(right, p.right_gray, "right", problem);
    if (!left_gray.empty() && !left_colour.empty() &&
        (left_colour.type() != CV_8UC3 || left_colour.size() != left.size())) {
        problem = "left colour image is " + describeSize(left_colour.size()) + " with " +
                  std::to_string(left_colour.channels()) +
                  " channels, not 8-bit BGR of the left image's size";
    }
    if (left_gray.empty() || right_gray.empty() || !problem.empty()) {
        p.last_right = cv::Mat();
        p.badFrame(out, problem);
        return;
    }
    if (p.last_frame_bad) {
        spdlog::info("frame {}: frames usable again", frame);
        p.last_frame_bad = false;
    }

    cv::Mat right_rectified = right_gray;
    if (p.rectifier.remaps()) {
        p.rectifier.rectifyPair(left_gray, right_gray, out.left_rectified, p.right_rectified);
        right_rectified = p.right_rectified;
    } else {
        p.rectifier.rectifyLeft(left_gray, out.left_rectified);
    }
    const Clock::time_point t_grey = Clock::now();
    // The colour left, for the outputs only, through the same maps.
    if (!left_colour.empty()) {
        p.rectifier.rectifyLeft(left_colour, out.left_rectified_colour);
    } else if (left.channels() == 3) {
        p.rectifier.rectifyLeft(left, out.left_rectified_colour);
    } else if (left.channels() == 4) {
        cv::cvtColor(left, p.left_bgr, cv::COLOR_BGRA2BGR);
        p.rectifier.rectifyLeft(p.left_bgr, out.left_rectified_colour);
    } else {
        out.left_rectified_colour.release();
    }
    const Clock::time_point t1 = Clock::now();

    // The matcher writes into the result's buffers (headers shared, nothing copied).
    MatchOutput match{out.disparity, out.confidence, out.near_field, p.coarse_only_px};
    p.last_right = right_rectified;
    p.matcher->compute(out.left_rectified, right_rectified,
                       regionPixels(p.settings.nearest.roi, out.left_rectified.size()), match);
    out.disparity = match.disparity_px;
    out.confidence = match.confidence;
    out.near_field = match.near_field;
    p.coarse_only_px = match.coarse_only_px;
    const Clock::time_point t2 = Clock::now();

    disparityToDepth(out.disparity, p.calibration.rectified, out.depth_m);
    const Clock::time_point t3 = Clock::now();

    // The region's unmeasured pixels, at the nearest other evidence says they may be: the
    // right camera cannot see them, or the coarse level alone matched them.
    // Row by row, in stripes over OpenCV's pool: the buffers are made before, so that no
    // stripe reallocates what another writes.
    const cv::Rect region = regionPixels(p.settings.nearest.roi, out.disparity.size());
    p.inferred_px.create(out.disparity.size(), CV_32FC1);
    if (p.inferred_depth_m.size() != out.disparity.size())
        p.inferred_depth_m = cv::Mat::zeros(out.disparity.size(), CV_32FC1);
    // A shadow's run is found along the whole row; the rest is needed in the region alone.
    forRowStripes(region.y, region.y + region.height, [&](int first, int end) {
        hiddenSurfaceBounds(out.disparity, first, end, p.inferred_px);
        const cv::Rect rows(region.x, first, region.width, end - first);
        if (!p.coarse_only_px.empty())
            nearerOf(p.coarse_only_px, rows, p.inferred_px);
        cv::Mat inferred_rows = p.inferred_depth_m(rows);
        disparityToDepth(p.inferred_px(rows), p.calibration.rectified, inferred_rows);
    });
    RegionMeasurement measured = p.nearest.measure(out.depth_m, out.confidence, out.near_field,
                                                   p.inferred_depth_m, p.settings.nearest);
    measured.out_of_view_pixels =
        outOfViewPixels(region, measured.percentile_depth_m, p.calibration.rectified);
    out.facts = regionFacts(measured, p.settings.nearest, p.nearFieldFacts(), stamp_ns, frame);
    out.reading = judgeReading(out.facts);
    const Clock::time_point t4 = Clock::now();

    // The outputs: the depth within the cap (counted in the cloud stage's time), and the
    // cloud from it.
    clearDepthBeyond(out.depth_m, static_cast<float>(p.max_output_depth_m));
    if (p.settings.compute_cloud)
        p.cloud.build(out.depth_m, out.left_rectified, p.calibration.rectified, out.cloud);
    else
        out.cloud.clear();
    const Clock::time_point t5 = Clock::now();
    if (p.settings.compute_cloud && !out.left_rectified_colour.empty())
        p.cloud.colours(out.depth_m, out.left_rectified_colour, out.cloud_colour);
    else
        out.cloud_colour.clear();
    const Clock::time_point t6 = Clock::now();

    out.timings.rectify_ms = msBetween(t0, t_grey);
    out.timings.colour_ms = out.left_rectified_colour.empty() ? 0.0 : msBetween(t_grey, t1);
    out.timings.match_ms = msBetween(t1, t2);
    out.timings.extended_range_ms = p.matcher->extendedRangeMs();
    out.timings.near_field_probe_ms = p.matcher->nearFieldProbeMs();
    out.timings.depth_ms = msBetween(t2, t3);
    out.timings.nearest_ms = msBetween(t3, t4);
    out.timings.cloud_ms = msBetween(t4, t5);
    out.timings.cloud_colour_ms = out.cloud_colour.empty() ? 0.0 : msBetween(t5, t6);
}

void StereoProcessor::updateSettings(const ProcessorSettings& settings)
{
    Impl& p = *impl_;
    // Everything that can throw happens before anything changes.
    const DisparityRange range = validateProcessorSettings(settings, p.calibration.rectified);
    if (p.matcher->kind() != settings.matcher.kind) {
        p.matcher = makeMatcher(settings.matcher, range);
    } else {
        p.matcher->configure(settings.matcher, range);
    }
    if (range.capped && (!p.range.capped || range.num_disparities != p.range.num_disparities))
        warnIfCapped(range, settings.matcher);
    p.range = range;
    p.settings = settings;
    p.max_output_depth_m =
        settings.output.max_depth_m.value_or(defaultMaxOutputDepth(p.calibration.rectified));
}

const cv::Mat& StereoProcessor::lastRightRectified() const
{
    return impl_->last_right;
}

const StereoCalibration& StereoProcessor::calibration() const
{
    return impl_->calibration;
}

const ProcessorSettings& StereoProcessor::settings() const
{
    return impl_->settings;
}

DisparityRange StereoProcessor::disparityRange() const
{
    return impl_->range;
}

LeftEdgeView StereoProcessor::regionLeftEdge() const
{
    const RectifiedGeometry& geometry = impl_->calibration.rectified;
    return leftEdgeView(regionPixels(impl_->settings.nearest.roi, toCv(geometry.image_size)),
                        impl_->range.last_disparity_px, geometry);
}

double StereoProcessor::maxOutputDepth() const
{
    return impl_->max_output_depth_m;
}

std::string StereoProcessor::matcherName() const
{
    return impl_->matcher->name();
}

} // namespace stereod
