#include "capture/side_by_side_source.hpp"

#include <cerrno>
#include <stdexcept>
#include <utility>

namespace stereod {

FrameSplitter::FrameSplitter(std::size_t slots, bool right_colour)
    : slots_(std::make_unique<Slot[]>(slots)), count_(slots), right_colour_(right_colour)
{
    for (std::size_t i = 0; i < count_; ++i) {
        slots_[i].halves[0].owner = this;
        slots_[i].halves[1].owner = this;
    }
}

FrameSplitter::~FrameSplitter() = default;

bool FrameSplitter::split(FrameHandle whole, StereoPair& pair) noexcept
{
    if (!whole)
        return false;
    for (std::size_t i = 0; i < count_; ++i) {
        Slot& slot = slots_[i];
        bool expected = false;
        if (!slot.in_use.compare_exchange_strong(expected, true, std::memory_order_acquire))
            continue;
        const int half_width = whole->image.cols / 2;
        const int rows = whole->image.rows;
        for (int side = 0; side < 2; ++side) {
            Frame& half = slot.halves[side];
            // A header over the whole frame's pixels: no copy, no allocation.
            const cv::Rect rect(side * half_width, 0, half_width, rows);
            half.image = whole->image(rect);
            if (!whole->colour.empty() && (side == 0 || right_colour_))
                half.colour = whole->colour(rect);
            else
                half.colour.release();
            half.stamp_ns = whole->stamp_ns;
            half.source_stamp_ns = whole->source_stamp_ns;
            half.sequence = whole->sequence;
        }
        slot.whole = std::move(whole);
        slot.holders.store(2, std::memory_order_release);
        pair.left = FrameHandle(&slot.halves[0]);
        pair.right = FrameHandle(&slot.halves[1]);
        return true;
    }
    return false;
}

void FrameSplitter::recycle(Frame* half) noexcept
{
    for (std::size_t i = 0; i < count_; ++i) {
        Slot& slot = slots_[i];
        if (half != &slot.halves[0] && half != &slot.halves[1])
            continue;
        if (slot.holders.fetch_sub(1, std::memory_order_acq_rel) == 1) {
            for (Frame& each : slot.halves) {
                each.image.release();
                each.colour.release();
            }
            slot.whole.reset(); // back to the camera
            slot.in_use.store(false, std::memory_order_release);
        }
        return;
    }
}

std::size_t FrameSplitter::inUse() const noexcept
{
    std::size_t count = 0;
    for (std::size_t i = 0; i < count_; ++i)
        count += slots_[i].in_use.load(std::memory_order_acquire) ? 1 : 0;
    return count;
}

namespace {

const SideBySideOptions& checked(const SideBySideOptions& options)
{
    if (options.camera.width % 2 != 0)
        throw std::invalid_argument("side-by-side camera " + options.camera.device +
                                    ": the frame width " + std::to_string(options.camera.width) +
                                    " is odd; the frame must hold two equal halves");
    return options;
}

} // namespace

SideBySideSource::SideBySideSource(SideBySideOptions options)
    : options_(checked(options)),
      // Every frame the camera can have out at once: the inbox, the one in hand, the
      // ring's pairs and the worker's.
      splitter_(options_.inbox_capacity + options_.ring_capacity + 3, options_.right_colour),
      inbox_(options_.inbox_capacity), camera_(options_.camera, 0, "side-by-side")
{
}

SideBySideSource::~SideBySideSource()
{
    stop();
}

int SideBySideSource::start(PairRing& ring)
{
    if (thread_.joinable())
        return -EBUSY;
    {
        std::lock_guard lock(error_mutex_);
        start_error_.clear();
    }
    ring_ = &ring;
    stop_requested_.store(false, std::memory_order_release);
    thread_ = std::thread([this] { run(); });
    const int rc = camera_.start(inbox_, &wake_);
    if (rc < 0) {
        const V4l2CameraStatus failed = camera_.status();
        {
            std::lock_guard lock(error_mutex_);
            start_error_ = "side-by-side camera " + failed.device + ": " + failed.camera.last_error;
        }
        stop();
        return rc;
    }
    return 0;
}

void SideBySideSource::stop() noexcept
{
    camera_.stop();
    if (thread_.joinable()) {
        stop_requested_.store(true, std::memory_order_release);
        wake_.fetch_add(1, std::memory_order_release);
        wake_.notify_all();
        thread_.join();
    }
    while (inbox_.tryPop()) {
    }
    ring_ = nullptr;
}

void SideBySideSource::run() noexcept
{
    for (;;) {
        const uint32_t seen = wake_.load(std::memory_order_acquire);
        if (stop_requested_.load(std::memory_order_acquire))
            return;
        while (std::optional<CapturedFrame> captured = inbox_.tryPop()) {
            StereoPair pair;
            if (!splitter_.split(std::move(captured->frame), pair)) {
                split_dropped_.fetch_add(1, std::memory_order_relaxed);
                continue;
            }
            pair.index = pairs_.fetch_add(1, std::memory_order_relaxed);
            ring_->push(std::move(pair));
        }
        wake_.wait(seen, std::memory_order_acquire);
    }
}

SourceStatus SideBySideSource::status() const
{
    SourceStatus out;
    out.kind = "side-by-side";
    const V4l2CameraStatus camera = camera_.status();
    out.state = camera.camera.state;
    {
        std::lock_guard lock(error_mutex_);
        out.last_error = !start_error_.empty() ? start_error_ : camera.camera.last_error;
    }
    CameraStatus entry = camera.camera;
    entry.dropped += inbox_.dropped() + split_dropped_.load(std::memory_order_relaxed);
    out.cameras.push_back(std::move(entry));
    out.pairs = pairs_.load(std::memory_order_relaxed);
    // Both halves come from one exposure: no skew, nothing unpaired.
    if (camera.camera.state == SourceState::Running && !camera.kernel_monotonic_stamps)
        out.warnings.push_back("side-by-side camera " + camera.device +
                               ": the driver gives no monotonic capture time; frames are "
                               "stamped at dequeue");
    return out;
}

cv::Size SideBySideSource::frameSize() const
{
    const cv::Size whole = camera_.frameSize();
    return {whole.width / 2, whole.height};
}

} // namespace stereod
