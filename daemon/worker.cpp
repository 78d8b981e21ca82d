#include "daemon/worker.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <system_error>

#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include "base/percentile.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/depth_io.hpp"

namespace stereod {

namespace {

// A pair whose depth cannot be trusted (a bad frame, cameras out of sync) carries no
// depth: a robot reading the depth stream must not act on numbers the reading refuses.
void clearDepth(DepthResult& result)
{
    if (!result.depth_m.empty())
        result.depth_m.setTo(0.0f);
    if (!result.disparity.empty())
        result.disparity.setTo(std::numeric_limits<float>::infinity());
    result.cloud.clear();
}

} // namespace

void logDisparityRange(const DisparityRange& range, const MatcherSettings& settings,
                       const std::string& matcher_name)
{
    spdlog::info("disparity range: {} disparities from {} ({}): sees from {:.2f} m",
                 range.num_disparities, range.min_disparity, matcher_name, range.closest_depth_m);
    if (range.capped)
        spdlog::warn("cannot see closer than {:.2f} m with {} disparities (matcher.min_depth_m "
                     "asks for {:.2f} m; matcher.max_num_disparities = {} caps the range)",
                     range.closest_depth_m, range.num_disparities, settings.min_depth_m,
                     settings.max_num_disparities);
}

void logRegionLeftEdge(const StereoProcessor& processor)
{
    const LeftEdgeView view = processor.regionLeftEdge();
    if (view.short_columns == 0)
        return;
    const int last = view.first_column + view.short_columns - 1;
    spdlog::warn("nearest.roi: its columns {} to {} ({:.0f} % of it) see no nearer than {:.3f} to "
                 "{:.3f} m, where the range measures from {:.3f} m; nearer than that there, a "
                 "surface is outside the right camera's view and the reading passes over it "
                 "(raise nearest.roi.x for the whole range in the whole region)",
                 view.first_column, last, 100.0 * view.short_columns / std::max(1, view.columns),
                 view.nearest_seen_m, view.last_short_seen_m,
                 processor.disparityRange().closest_depth_m);
}

void copyRawPair(const StereoPair& pair, RawPair& raw)
{
    raw.present = false;
    if (!pair.left || !pair.right)
        return;
    pair.left->image.copyTo(raw.left);
    pair.right->image.copyTo(raw.right);
    // Colour as captured, where the camera kept it; a grey source never allocates it.
    for (auto [frame, colour] : {std::pair{pair.left.get(), &raw.left_colour},
                                 std::pair{pair.right.get(), &raw.right_colour}}) {
        if (frame->colour.empty())
            colour->release();
        else
            frame->colour.copyTo(*colour);
    }
    raw.left_stamp_ns = pair.left->source_stamp_ns;
    raw.right_stamp_ns = pair.right->source_stamp_ns;
    raw.present = true;
}

Worker::Worker(PairRing& ring, Publisher& publisher, StereoProcessor* processor, double max_skew_ms)
    : ring_(ring), publisher_(publisher), processor_(processor), max_skew_ms_(max_skew_ms),
      finished_fd_(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC))
{
    if (!finished_fd_)
        throw std::system_error(errno, std::generic_category(), "worker: eventfd");
    refreshRange();
}

Worker::~Worker()
{
    ring_.stop();
    join();
    delete pending_settings_.exchange(nullptr, std::memory_order_acq_rel);
    delete pending_zones_.exchange(nullptr, std::memory_order_acq_rel);
}

void Worker::start()
{
    thread_ = std::thread([this] { run(); });
}

void Worker::join()
{
    if (thread_.joinable())
        thread_.join();
}

void Worker::updateSettings(const ProcessorSettings& settings)
{
    auto fresh = std::make_unique<ProcessorSettings>(settings);
    std::unique_ptr<ProcessorSettings> replaced(
        pending_settings_.exchange(fresh.release(), std::memory_order_acq_rel));
}

void Worker::updateZones(const ZonesSettings& zones)
{
    auto fresh = std::make_unique<ZonesSettings>(zones);
    std::unique_ptr<ZonesSettings> replaced(
        pending_zones_.exchange(fresh.release(), std::memory_order_acq_rel));
}

void Worker::refreshRange()
{
    stats_.range = processor_ != nullptr ? processor_->disparityRange() : DisparityRange{};
    stats_.max_output_depth_m = processor_ != nullptr ? processor_->maxOutputDepth() : 0.0;
    stats_.matcher.assign(processor_ != nullptr ? processor_->matcherName() : "none");
}

void Worker::applyPendingSettings()
{
    if (StereoProcessor* processor =
            pending_processor_.exchange(nullptr, std::memory_order_acquire)) {
        processor_ = processor;
        health_ = pending_health_;
        refreshRange();
    }
    if (std::unique_ptr<ZonesSettings> zones{
            pending_zones_.exchange(nullptr, std::memory_order_acq_rel)}) {
        try {
            zones_.reconfigure(*zones);
            spdlog::info("keep-out zones in force: {}", zones->zones.size());
        } catch (const std::exception& e) {
            spdlog::error("new keep-out zones refused, the previous ones stay in force: {}",
                          e.what());
        }
    }
    std::unique_ptr<ProcessorSettings> settings(
        pending_settings_.exchange(nullptr, std::memory_order_acq_rel));
    if (!settings || processor_ == nullptr)
        return;
    try {
        processor_->updateSettings(*settings);
        refreshRange();
        spdlog::info("new processing settings in force");
        logDisparityRange(stats_.range, settings->matcher, std::string(stats_.matcher.view()));
        logRegionLeftEdge(*processor_);
    } catch (const std::exception& e) {
        spdlog::error("new processing settings refused, the previous ones stay in force: {}",
                      e.what());
    }
}

void Worker::run()
{
    const auto next = [this] { return takes_every_pair_ ? ring_.pop() : ring_.popNewest(); };
    while (std::optional<StereoPair> pair = next()) {
        // Once stopped, the pairs still queued are given back unprocessed: nobody waits
        // for their results, and the stop must not wait for them either.
        if (ring_.stopped())
            continue;
        busy_since_ns_.store(monotonicNowNs(), std::memory_order_release);
        // processPair() turns failures of the chain into readings; this catches what is
        // left (the conversion for sending, say), so that nothing leaves the thread.
        try {
            applyPendingSettings();
            processPair(*pair);
        } catch (const std::exception& e) {
            logFailure(pair->index, e.what());
        } catch (...) {
            logFailure(pair->index, "unknown error");
        }
        busy_since_ns_.store(0, std::memory_order_release);
    }
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = ::write(finished_fd_.get(), &one, sizeof one);
}

bool Worker::waitFinished(int64_t deadline_ns) const
{
    pollfd finished{finished_fd_.get(), POLLIN, 0};
    for (;;) {
        const int64_t left_ns = deadline_ns - monotonicNowNs();
        // Rounded up, so that a wait never ends before the deadline it was given.
        const int timeout_ms =
            left_ns <= 0
                ? 0
                : static_cast<int>(std::min<int64_t>((left_ns + 999'999) / 1'000'000, 60'000));
        const int ready = ::poll(&finished, 1, timeout_ms);
        if (ready > 0)
            return true;
        if ((ready == 0 && timeout_ms == 0) || (ready < 0 && errno != EINTR))
            return false;
    }
}

void Worker::logFailure(uint64_t frame, const char* what)
{
    log_limiter_.log(spdlog::level::err, "worker.pair_failed", monotonicNowNs(),
                     "frame {}: the pair could not be processed: {}", frame, what);
}

void Worker::processPair(StereoPair& pair)
{
    PublishedFrame& slot = publisher_.writeSlot();
    DepthResult& result = slot.result;
    slot.reason_message.clear();
    slot.skew_ns = pair.skewNs();
    const int64_t stamp_ns = pair.stampNs();
    const uint64_t frame = pair.index;
    if (publisher_.rawWanted(monotonicNowNs()))
        copyRawPair(pair, slot.raw);
    else
        slot.raw.present = false;

    // The facts of the pair; the verdict is judgeReading()'s alone.
    ReadingFacts& facts = result.facts;
    bool processed = false;
    if (processor_ == nullptr) {
        facts = ReadingFacts{};
        facts.calibrated = false;
    } else if (!pair.left || !pair.right) {
        facts = ReadingFacts{};
        facts.pair = PairOutcome::BadFrame;
        slot.reason_message.assign("a frame is missing");
    } else {
        try {
            processor_->process(pair.left->image, pair.left->colour, pair.right->image, stamp_ns,
                                frame, result);
            processed = facts.pair == PairOutcome::Processed;
            // Before the frames go back: with a rectified-only calibration the right image
            // the matcher saw is the frame itself.
            if (health_ != nullptr && processed && health_->due(monotonicNowNs()))
                health_->offer(result.left_rectified, processor_->lastRightRectified(), stamp_ns);
            const cv::Size calibrated = toCv(processor_->calibration().rectified.image_size);
            if (!processed &&
                (pair.left->image.size() != calibrated || pair.right->image.size() != calibrated))
                slot.reason_message.format("frames %dx%d and %dx%d, calibration %dx%d",
                                           pair.left->image.cols, pair.left->image.rows,
                                           pair.right->image.cols, pair.right->image.rows,
                                           calibrated.width, calibrated.height);
        } catch (const std::exception& e) {
            facts = ReadingFacts{};
            facts.pair = PairOutcome::BadFrame;
            slot.reason_message.assign(e.what());
            logFailure(frame, e.what());
        } catch (...) {
            facts = ReadingFacts{};
            facts.pair = PairOutcome::BadFrame;
            slot.reason_message.assign("unknown error");
            logFailure(frame, "unknown error");
        }
    }
    // The buffers go back to the source now, not when the slot is reused.
    pair.left.reset();
    pair.right.reset();

    facts.stamp_ns = stamp_ns;
    facts.frame = frame;
    facts.skew_ms = std::abs(static_cast<double>(slot.skew_ns)) / 1e6;
    facts.max_skew_ms = max_skew_ms_;
    // Calibration health: a suspect calibration marks the reading, and withholds it when it
    // failed and the configuration asks for that.
    facts.calibration_suspect = false;
    facts.calibration_failed = false;
    facts.calibration_row_offset_px = 0.0;
    facts.withhold_when_failed = withhold_when_failed_.load(std::memory_order_relaxed);
    if (health_ != nullptr && processed) {
        const HealthState health = health_->state();
        facts.calibration_suspect =
            health == HealthState::Degraded || health == HealthState::Failed;
        facts.calibration_failed = health == HealthState::Failed;
        facts.calibration_row_offset_px = health_->rowOffsetPx();
    }
    result.reading = judgeReading(facts);
    Reading& reading = result.reading;
    result.stamp_ns = stamp_ns;
    result.frame = frame;
    if (reading.reason == NoReadingReason::OutOfSync)
        ++stats_.out_of_sync;

    // Depth is kept when only the region lacked data (too few valid pixels, nothing in
    // range): the picture itself is sound. It is cleared when the pair is not.
    slot.depth_valid = processed && !result.depth_m.empty();
    if (reading.reason == NoReadingReason::BadFrame) {
        ++stats_.bad_frames;
        clearDepth(result);
        slot.depth_valid = false;
    } else if (reading.reason == NoReadingReason::OutOfSync) {
        clearDepth(result);
        slot.depth_valid = false;
    }

    // Keep-out zones from the depth the reading trusts; without it, every zone is unknown
    // for this pair (its hysteresis untouched) with the reading's reason.
    slot.camera_pose = zones_.settings().camera_pose;
    const int64_t zones_start_ns = monotonicNowNs();
    if (!zones_.settings().zones.empty()) {
        const std::vector<ZoneReading>& zones =
            slot.depth_valid && processor_ != nullptr
                ? zones_.update(result.depth_m, processor_->calibration().rectified,
                                stats_.range.closest_depth_m, stamp_ns, frame)
                : zones_.markUnknown(reasonCode(reading.reason), stamp_ns, frame);
        // Element-wise assignment: the names keep their buffers from frame to frame.
        slot.zones.resize(zones.size());
        std::copy(zones.begin(), zones.end(), slot.zones.begin());
    } else {
        slot.zones.clear();
    }

    const int64_t publish_start_ns = monotonicNowNs();
    zones_ms_.add(static_cast<double>(publish_start_ns - zones_start_ns) / 1e6);
    if (!result.depth_m.empty())
        depthToMillimetres(result.depth_m, slot.depth_mm);
    else
        slot.depth_mm.release();

    // Stage times only of pairs that went through the chain.
    if (processed && reading.reason != NoReadingReason::BadFrame) {
        rectify_ms_.add(result.timings.rectify_ms);
        match_ms_.add(result.timings.match_ms);
        depth_ms_.add(result.timings.depth_ms);
        nearest_ms_.add(result.timings.nearest_ms);
        cloud_ms_.add(result.timings.cloud_ms);
        extended_ms_.add(result.timings.extended_range_ms);
        probe_ms_.add(result.timings.near_field_probe_ms);
    }
    ++stats_.frames;
    processed_.add(publish_start_ns);
    stats_.fps = processed_.perSecond();
    stats_.stage_mean_ms.rectify_ms = mean(rectify_ms_);
    stats_.stage_mean_ms.match_ms = mean(match_ms_);
    stats_.stage_mean_ms.depth_ms = mean(depth_ms_);
    stats_.stage_mean_ms.nearest_ms = mean(nearest_ms_);
    stats_.stage_mean_ms.cloud_ms = mean(cloud_ms_);
    stats_.stage_mean_ms.extended_range_ms = mean(extended_ms_);
    stats_.stage_mean_ms.near_field_probe_ms = mean(probe_ms_);
    stats_.zones_mean_ms = mean(zones_ms_);
    const int64_t published_ns = monotonicNowNs();
    publish_ms_.add(static_cast<double>(published_ns - publish_start_ns) / 1e6);
    stats_.publish_mean_ms = mean(publish_ms_);
    // Latency as a robot sees it: from the pair's capture stamp (CLOCK_MONOTONIC) to its
    // result going out. A pair whose stamp is not on this clock gives no figure.
    if (stamp_ns > 0 && stamp_ns <= published_ns) {
        latency_ms_.add(static_cast<double>(published_ns - stamp_ns) / 1e6);
        const std::size_t n = latency_ms_.size();
        for (std::size_t i = 0; i < n; ++i)
            latency_sorted_[i] = latency_ms_[i];
        const auto sorted_end = latency_sorted_.begin() + static_cast<std::ptrdiff_t>(n);
        stats_.latency_p50_ms = lowerLinearPercentile(latency_sorted_.begin(), sorted_end, 50.0);
        stats_.latency_p99_ms = lowerLinearPercentile(latency_sorted_.begin(), sorted_end, 99.0);
    }
    slot.stats = stats_;
    publisher_.publish();
}

} // namespace stereod
