#include "replay/replay_source.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <system_error>
#include <utility>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <spdlog/spdlog.h>

#include "replay/image_decode.hpp"
#include "replay/image_message.hpp"

namespace stereod {

namespace {

constexpr int kLeft = 0;
constexpr int kRight = 1;
constexpr const char* kSideName[2] = {"left", "right"};
constexpr int64_t kForever = std::numeric_limits<int64_t>::max();

std::string sizeText(cv::Size size)
{
    return std::to_string(size.width) + "x" + std::to_string(size.height);
}

// A decoded image into a pooled frame of its size: the grey, and where the frame has a
// colour plane the image's colour, or its grey when it has none (a grey image in a colour
// recording). copyTo() and cvtColor() write into the pooled buffers: no allocation.
void fillFrame(const cv::Mat& grey, const cv::Mat& colour, Frame& frame)
{
    grey.copyTo(frame.image);
    if (frame.colour.empty())
        return;
    if (colour.empty())
        cv::cvtColor(grey, frame.colour, cv::COLOR_GRAY2BGR);
    else
        colour.copyTo(frame.colour);
}

} // namespace

ReplaySource::ReplaySource(ReplayOptions options) : options_(std::move(options))
{
    try {
        if (isMcapFile(options_.path)) {
            openBag();
        } else {
            recording_ = openRecording(options_.path, options_.fps);
        }
    } catch (const RecordingError& e) {
        open_error_ = -e.code();
        fail(e.what());
        return;
    } catch (const mcap::McapError& e) {
        open_error_ = -e.code();
        fail(e.what());
        return;
    }
    for (const std::string& problem : recording_.problems)
        spdlog::warn("replay: {} (row skipped)", problem);
    if (recording_.bad_rows > recording_.problems.size())
        spdlog::warn("replay: {}: {} more malformed rows skipped", recording_.dir,
                     recording_.bad_rows - recording_.problems.size());

    warned_.assign(recording_.entries.size() * 2, 0);
    planSchedule();

    // The first readable pair fixes the frame size (and so the pool).
    std::string first_problem;
    int first_code = 0;
    for (std::size_t i = 0; i < recording_.entries.size(); ++i) {
        BadPair bad;
        if (decodePair(i, bad)) {
            frame_size_ = left_image_.size();
            break;
        }
        if (first_problem.empty()) {
            first_problem = bad.path + ": " + bad.reason;
            first_code = bad.code;
        }
    }
    if (frame_size_.empty()) {
        open_error_ = -(first_code != 0 ? first_code : ENOENT);
        fail(recording_.dir + ": none of its " + std::to_string(recording_.entries.size()) +
             " pairs is readable (first: " + first_problem + ")");
        return;
    }
    // A colour first pair gives that side's frames a colour plane (a grey pair later in
    // the same recording fills it with its grey); the right frames stay grey unless asked.
    const std::size_t pairs = std::max<std::size_t>(options_.pool_pairs, 1);
    const bool left_colour = !left_colour_.empty();
    const bool right_colour = !right_colour_.empty();
    const std::size_t colour_sides = (left_colour ? 1 : 0) + (right_colour ? 1 : 0);
    if (colour_sides < 2)
        pool_ = std::make_unique<FramePool>((2 - colour_sides) * pairs, frame_size_);
    if (colour_sides > 0)
        colour_pool_ =
            std::make_unique<FramePool>(colour_sides * pairs, frame_size_, CV_8UC1, true);
    left_pool_ = left_colour ? colour_pool_.get() : pool_.get();
    right_pool_ = right_colour ? colour_pool_.get() : pool_.get();
    const char* in_colour = colour_sides == 2 ? " (both in colour)"
                            : left_colour     ? " (left in colour)"
                            : right_colour    ? " (right in colour)"
                                              : "";
    spdlog::info("replay: {}: {} pairs of {}{}{}, {}{}", recording_.dir, recording_.entries.size(),
                 sizeText(frame_size_), in_colour, recording_.has_index ? "" : " (plain folder)",
                 kReplayPacings.name(options_.pacing), options_.loop ? ", looping" : "");
}

ReplaySource::~ReplaySource()
{
    stop();
    for (std::unique_ptr<FramePool>* pool : {&pool_, &colour_pool_}) {
        if (*pool && (*pool)->inUse() > 0) {
            // Frames still out (a ring not drained): freeing the pool would leave them
            // pointing into freed memory. Leaking it is the lesser evil; say so loudly.
            spdlog::error("replay: {}: destroyed with {} frames still in use; their pool is "
                          "leaked (drain the ring before destroying the source)",
                          recording_.dir, (*pool)->inUse());
            static_cast<void>(pool->release());
        }
    }
}

int ReplaySource::start(PairRing& ring)
{
    if (thread_.joinable()) {
        // Running, or trying again after a pass with nothing readable.
        if (!thread_done_.load(std::memory_order_acquire))
            return -EBUSY;
        thread_.join(); // a replay that finished on its own
    }
    if (open_error_ != 0) {
        state_.store(SourceState::Failed, std::memory_order_release);
        return open_error_;
    }
    {
        std::lock_guard<std::mutex> lock(status_mutex_);
        last_error_.clear();
    }
    ring_ = &ring;
    stop_requested_.store(false, std::memory_order_release);
    fps_.restart();
    state_.store(SourceState::Running, std::memory_order_release);
    try {
        thread_done_.store(false, std::memory_order_release);
        thread_ = std::thread([this] {
            run();
            thread_done_.store(true, std::memory_order_release);
        });
    } catch (const std::system_error& e) {
        ring_ = nullptr;
        fail(recording_.dir + ": cannot start the replay thread: " + e.what());
        return -(e.code().value() != 0 ? e.code().value() : EAGAIN);
    }
    return 0;
}

void ReplaySource::stop() noexcept
{
    {
        std::lock_guard<std::mutex> lock(wake_mutex_);
        stop_requested_.store(true, std::memory_order_release);
    }
    wake_cv_.notify_all();
    // A lockstep producer may sit in pushWait() on a full ring: only stopping the ring
    // releases it.
    if (ring_ != nullptr && options_.pacing == ReplayPacing::Lockstep)
        ring_->stop();
    if (thread_.joinable())
        thread_.join();
    ring_ = nullptr;
    SourceState running = SourceState::Running;
    state_.compare_exchange_strong(running, SourceState::Stopped, std::memory_order_acq_rel);
}

void ReplaySource::planSchedule()
{
    const std::vector<RecordingEntry>& entries = recording_.entries;
    const std::size_t count = entries.size();
    // One frame period: the mean of the recorded steps forward, or the nominal rate.
    int64_t forward_ns = 0;
    std::size_t forward_steps = 0;
    for (std::size_t i = 1; i < count; ++i) {
        const int64_t step_ns =
            saturatingSubNs(entries[i].left_stamp_ns, entries[i - 1].left_stamp_ns);
        if (step_ns > 0 && forward_ns <= std::numeric_limits<int64_t>::max() - step_ns) {
            forward_ns += step_ns;
            ++forward_steps;
        }
    }
    period_ns_ = forward_steps > 0
                     ? std::max<int64_t>(forward_ns / static_cast<int64_t>(forward_steps), 1)
                     : std::llround(1e9 / (options_.fps > 0.0 ? options_.fps : 10.0));

    // Each pair is due its recorded step after the one before; a stamp that steps back
    // (a recording spliced from two runs) or repeats the one before (a bag whose stamps
    // are all equal would otherwise come as fast as it decodes) comes one period after its
    // predecessor, and the pace goes on from the new stamps.
    schedule_ns_.assign(std::max<std::size_t>(count, 1), 0);
    std::size_t steps_back = 0;
    std::size_t first_back = 0;
    std::size_t repeats = 0;
    std::size_t first_repeat = 0;
    for (std::size_t i = 1; i < count; ++i) {
        int64_t step_ns = saturatingSubNs(entries[i].left_stamp_ns, entries[i - 1].left_stamp_ns);
        if (step_ns < 0) {
            if (steps_back++ == 0)
                first_back = i;
            step_ns = period_ns_;
        } else if (step_ns == 0) {
            if (repeats++ == 0)
                first_repeat = i;
            step_ns = period_ns_;
        }
        schedule_ns_[i] =
            schedule_ns_[i - 1] +
            std::min(step_ns, std::numeric_limits<int64_t>::max() / 4 - schedule_ns_[i - 1]);
    }
    if (steps_back > 0)
        spdlog::warn("replay: {}: the stamps step back {} time{}, first at pair {} ({} ns "
                     "after {} ns; a recording spliced from two runs?): each such pair comes "
                     "one frame period ({:.1f} ms) after the one before, and the pace goes on "
                     "from the new stamps",
                     recording_.dir, steps_back, steps_back == 1 ? "" : "s",
                     entries[first_back].index, entries[first_back].left_stamp_ns,
                     entries[first_back - 1].left_stamp_ns, static_cast<double>(period_ns_) / 1e6);
    if (repeats > 0)
        spdlog::warn("replay: {}: {} pair{} repeat the stamp of the pair before, first pair {} "
                     "({} ns): each comes one frame period ({:.1f} ms) after the one before",
                     recording_.dir, repeats, repeats == 1 ? "" : "s", entries[first_repeat].index,
                     entries[first_repeat].left_stamp_ns, static_cast<double>(period_ns_) / 1e6);
}

void ReplaySource::openBag()
{
    bag_ = std::make_unique<mcap::Reader>(options_.path);
    if (bag_->truncated())
        spdlog::warn("replay: {}: {}; replaying the pairs before it", options_.path,
                     bag_->problem());
    McapStereoIndex index;
    try {
        index = indexMcapStereo(*bag_, options_.left_topic, options_.right_topic);
    } catch (const mcap::McapError& e) {
        // What the scan stopped at is most likely why nothing fits: say it in the refusal.
        if (!bag_->truncated())
            throw;
        throw mcap::McapError(std::string(e.what()) + "; the bag is damaged: " + bag_->problem(),
                              e.code());
    }
    for (const std::string& note : index.notes)
        spdlog::info("replay: {}: {}", options_.path, note);
    for (const std::string& problem : index.problems)
        spdlog::warn("replay: {}: {}", options_.path, problem);
    if (index.unpaired_left + index.unpaired_right > 0)
        spdlog::warn("replay: {}: {} left and {} right images have no partner within half a "
                     "frame period and are skipped",
                     options_.path, index.unpaired_left, index.unpaired_right);
    recording_.dir = options_.path;
    recording_.has_index = true;
    recording_.entries.reserve(index.pairs.size());
    for (std::size_t i = 0; i < index.pairs.size(); ++i) {
        RecordingEntry entry;
        entry.index = i;
        entry.left_stamp_ns = index.pairs[i].left_stamp_ns;
        entry.right_stamp_ns = index.pairs[i].right_stamp_ns;
        // For messages: which message of the bag.
        entry.left_path =
            options_.path + " " + index.left_topic + " @" + std::to_string(entry.left_stamp_ns);
        entry.right_path =
            options_.path + " " + index.right_topic + " @" + std::to_string(entry.right_stamp_ns);
        recording_.entries.push_back(std::move(entry));
    }
    bag_pairs_ = std::move(index.pairs);
    bag_camera_info_ = std::move(index.camera_info);
}

bool ReplaySource::decodePair(std::size_t i, BadPair& bad)
{
    const RecordingEntry& entry = recording_.entries[i];
    if (bag_) {
        // As for files below: each side is checked against the size it must have before
        // it is decoded, so the message blamed is the one at fault.
        bad.code = EINVAL;
        try {
            const bool decoded = options_.keep_colour
                                     ? decodeMcapImage(*bag_, bag_pairs_[i].left, left_image_,
                                                       left_colour_, bad.reason, frame_size_)
                                     : decodeMcapImage(*bag_, bag_pairs_[i].left, left_image_,
                                                       bad.reason, frame_size_);
            if (!decoded) {
                bad.side = kLeft;
                bad.path = entry.left_path;
                return false;
            }
            const cv::Size right_size = frame_size_.empty() ? left_image_.size() : frame_size_;
            const bool right_decoded =
                options_.keep_right_colour
                    ? decodeMcapImage(*bag_, bag_pairs_[i].right, right_image_, right_colour_,
                                      bad.reason, right_size)
                    : decodeMcapImage(*bag_, bag_pairs_[i].right, right_image_, bad.reason,
                                      right_size);
            if (!right_decoded) {
                bad.side = kRight;
                bad.path = entry.right_path;
                return false;
            }
        } catch (const std::exception& e) {
            // A chunk that went bad since the index was made (a file being rewritten), or
            // memory that ran out reading it.
            bad.side = kLeft;
            bad.path = entry.left_path;
            bad.reason = e.what();
            return false;
        }
    } else {
        // Each side is checked against the size it must have before it is decoded: the
        // replay's frame size once known, else the left image's for the right one. So the
        // file blamed is the one at fault, and a decompression bomb is never decoded.
        const std::string replay_size =
            frame_size_.empty()
                ? std::string()
                : "the replay is " + sizeText(frame_size_) + " (its first readable pair)";
        if (!decodeImageFile(entry.left_path, frame_size_, replay_size, file_bytes_, left_image_,
                             bad.reason, bad.code,
                             options_.keep_colour ? &left_colour_ : nullptr)) {
            bad.side = kLeft;
            bad.path = entry.left_path;
            return false;
        }
        const std::string left_size =
            frame_size_.empty() ? "its left image is " + sizeText(left_image_.size()) : replay_size;
        if (!decodeImageFile(entry.right_path, left_image_.size(), left_size, file_bytes_,
                             right_image_, bad.reason, bad.code,
                             options_.keep_right_colour ? &right_colour_ : nullptr)) {
            bad.side = kRight;
            bad.path = entry.right_path;
            return false;
        }
    }
    return true;
}

void ReplaySource::reportBadPair(std::size_t i, const BadPair& bad)
{
    bad_frames_[bad.side].fetch_add(1, std::memory_order_relaxed);
    uint8_t& warned = warned_[2 * i + static_cast<std::size_t>(bad.side)];
    if (warned != 0)
        return;
    warned = 1;
    spdlog::warn("replay: {}: {} (pair {} skipped; said once per file)", bad.path, bad.reason,
                 recording_.entries[i].index);
    std::lock_guard<std::mutex> lock(status_mutex_);
    camera_error_[bad.side] = bad.path + ": " + bad.reason;
}

FrameHandle ReplaySource::acquireFrame(FramePool& pool, bool wait)
{
    for (;;) {
        FrameHandle frame = pool.acquire();
        if (frame || !wait)
            return frame;
        // Lockstep with every buffer held downstream (pool_pairs smaller than the ring
        // plus what the consumer keeps): poll until one comes back; the pool has no
        // wake-up of its own.
        if (!sleepUntil(monotonicNowNs() + 1'000'000))
            return FrameHandle();
    }
}

bool ReplaySource::sleepUntil(int64_t deadline_ns)
{
    // Waits are cut into pieces of at most an hour, so a recording with absurd stamp
    // gaps cannot overflow the clock arithmetic.
    constexpr int64_t kMaxPieceNs = int64_t{3600} * 1'000'000'000;
    std::unique_lock<std::mutex> lock(wake_mutex_);
    for (;;) {
        if (stop_requested_.load(std::memory_order_acquire))
            return false;
        if (deadline_ns == kForever) {
            wake_cv_.wait(lock);
            continue;
        }
        const int64_t now_ns = monotonicNowNs();
        if (now_ns >= deadline_ns)
            return true;
        wake_cv_.wait_for(lock,
                          std::chrono::nanoseconds(std::min(deadline_ns - now_ns, kMaxPieceNs)));
    }
}

void ReplaySource::recordDelivery(int64_t stamp_ns, int64_t skew_ns) noexcept
{
    fps_.add(stamp_ns);

    // Single writer: plain load/store suffice for the running sums.
    skew_.add(skew_ns);
    frames_[kLeft].fetch_add(1, std::memory_order_relaxed);
    frames_[kRight].fetch_add(1, std::memory_order_relaxed);
    pairs_.fetch_add(1, std::memory_order_release);
}

std::string ReplaySource::lastBadPair() const
{
    std::lock_guard<std::mutex> lock(status_mutex_);
    return camera_error_[kLeft].empty() ? camera_error_[kRight] : camera_error_[kLeft];
}

void ReplaySource::fail(const std::string& message)
{
    {
        std::lock_guard<std::mutex> lock(status_mutex_);
        last_error_ = message;
    }
    state_.store(SourceState::Failed, std::memory_order_release);
}

void ReplaySource::run() noexcept
{
    const std::vector<RecordingEntry>& entries = recording_.entries;
    const std::size_t count = entries.size();
    const bool paced = options_.pacing == ReplayPacing::Paced;
    const int64_t period_ns = period_ns_;
    // A loop goes on one period after the last pair, as the recording would have.
    const int64_t loop_ns = saturatingAddNs(schedule_ns_.back(), period_ns);

    int64_t base_ns = monotonicNowNs(); // when the first pair of this pass is due
    int64_t retry_ns = kRetryMinNs;     // the wait after a pass with nothing readable
    bool unreadable = false;            // the last pass had nothing readable
    for (;;) {
        const uint64_t pass = next_pass_++;
        uint64_t readable = 0;
        uint64_t delivered = 0;
        for (std::size_t i = 0; i < count; ++i) {
            if (stop_requested_.load(std::memory_order_acquire))
                return;
            BadPair bad;
            if (!decodePair(i, bad)) {
                reportBadPair(i, bad);
                continue;
            }
            ++readable;
            const RecordingEntry& entry = entries[i];

            // Frames from the pool: lock-free; lockstep waits for a free one instead of
            // dropping the pair.
            StereoPair pair;
            pair.left = acquireFrame(*left_pool_, !paced);
            if (pair.left)
                pair.right = acquireFrame(*right_pool_, !paced);
            if (!pair.right) {
                if (stop_requested_.load(std::memory_order_acquire))
                    return;
                dropped_.fetch_add(1, std::memory_order_relaxed); // as a camera would
                continue;
            }
            // Same size and type: copyTo() writes into the pooled buffers, no allocation.
            fillFrame(left_image_, left_colour_, *pair.left);
            fillFrame(right_image_, right_colour_, *pair.right);
            const uint64_t number = pass * count + i;
            pair.index = number;
            pair.left->sequence = number;
            pair.right->sequence = number;
            pair.left->source_stamp_ns = entry.left_stamp_ns;
            pair.right->source_stamp_ns = entry.right_stamp_ns;
            const int64_t skew_ns = saturatingSubNs(entry.right_stamp_ns, entry.left_stamp_ns);

            if (paced) {
                // The pacing sleep is the only lock this thread takes on its way, and it
                // is the stop() wake-up mutex, never shared with the consumer.
                const int64_t due_ns = saturatingAddNs(base_ns, schedule_ns_[i]);
                if (!sleepUntil(due_ns))
                    return;
                // Fell behind (decoding slower than the recorded rate): shift the schedule
                // rather than burst to catch up, as a camera would.
                const int64_t late_ns = monotonicNowNs() - due_ns;
                if (late_ns > period_ns)
                    base_ns = saturatingAddNs(base_ns, late_ns);
            }

            // Delivery: stamps, then the ring. From here to the counters: atomics only.
            const int64_t now_ns = monotonicNowNs();
            pair.left->stamp_ns = now_ns;
            pair.right->stamp_ns = saturatingAddNs(now_ns, skew_ns);
            if (paced) {
                ring_->push(std::move(pair)); // drop-oldest; the ring counts the drop
            } else if (!ring_->pushWait(std::move(pair))) {
                // The ring was stopped under us: the consumer is gone. Nothing more can
                // be delivered; wait for stop().
                sleepUntil(kForever);
                return;
            }
            recordDelivery(now_ns, skew_ns);
            ++delivered;
        }

        if (readable == 0) {
            // Files removed or damaged, or the process out of descriptors or memory for the
            // moment: like a camera that vanished, the replay tries again, backing off, and
            // goes on when the pairs are readable again (status says Failed meanwhile).
            if (!unreadable)
                spdlog::error("replay: {}: no pair readable in a whole pass (last: {}); trying "
                              "again every {} s at most",
                              recording_.dir, lastBadPair(), kRetryMaxNs / 1'000'000'000);
            unreadable = true;
            fail(recording_.dir + ": no pair of the " + std::to_string(count) +
                 " could be read in the last pass (files removed or damaged, or the process "
                 "out of descriptors?); trying again");
            if (!sleepUntil(saturatingAddNs(monotonicNowNs(), retry_ns)))
                return;
            retry_ns = std::min(retry_ns * 2, kRetryMaxNs);
            base_ns = monotonicNowNs();
            continue;
        }
        if (unreadable) {
            unreadable = false;
            retry_ns = kRetryMinNs;
            {
                std::lock_guard<std::mutex> lock(status_mutex_);
                last_error_.clear();
            }
            SourceState failed = SourceState::Failed;
            state_.compare_exchange_strong(failed, SourceState::Running, std::memory_order_acq_rel);
            spdlog::info("replay: {}: pairs readable again ({} in the last pass)", recording_.dir,
                         readable);
        }
        if (!options_.loop) {
            state_.store(SourceState::Finished, std::memory_order_release);
            spdlog::info("replay: {}: finished after {} pairs", recording_.dir,
                         pairs_.load(std::memory_order_relaxed));
            return;
        }
        base_ns = saturatingAddNs(base_ns, loop_ns);
    }
}

bool ReplaySource::keepsEveryPair() const noexcept
{
    return options_.pacing == ReplayPacing::Lockstep;
}

SourceStatus ReplaySource::status() const
{
    SourceStatus out;
    out.kind = "replay";
    out.state = state_.load(std::memory_order_acquire);
    out.pairs = pairs_.load(std::memory_order_acquire);
    std::string camera_error[2];
    {
        std::lock_guard<std::mutex> lock(status_mutex_);
        out.last_error = last_error_;
        camera_error[kLeft] = camera_error_[kLeft];
        camera_error[kRight] = camera_error_[kRight];
    }
    const double fps = out.state == SourceState::Running ? fps_.perSecond() : 0.0;
    for (int side : {kLeft, kRight}) {
        CameraStatus camera;
        camera.name = kSideName[side];
        camera.state = out.state;
        camera.last_error = std::move(camera_error[side]);
        camera.fps = fps;
        camera.frames = frames_[side].load(std::memory_order_relaxed);
        camera.dropped = dropped_.load(std::memory_order_relaxed);
        camera.bad_frames = bad_frames_[side].load(std::memory_order_relaxed);
        out.cameras.push_back(std::move(camera));
    }

    const RollingSummary skew = skew_.summary();
    out.skew_mean_ms = skew.mean_abs_ns / 1e6;
    out.skew_max_ms = static_cast<double>(skew.max_abs_ns) / 1e6;
    out.skew_p99_ms = static_cast<double>(skew.p99_abs_ns) / 1e6;
    return out;
}

} // namespace stereod
