#include "capture/v4l2_camera.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <thread>
#include <utility>

#include <fmt/format.h>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <strings.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include "base/latest_text.hpp"
#include "base/rate_estimate.hpp"
#include "base/system_error.hpp"
#include "base/unique_fd.hpp"
#include "capture/format_choice.hpp"
#include "capture/frame_decoder.hpp"
#include "capture/frame_pool.hpp"
#include "capture/v4l2_device.hpp"

namespace stereod {

namespace {

// Where each kernel buffer of a BufferSet is. Only a releasing holder moves Held to
// Returned; everything else happens on the capture thread.
enum BufferState : uint8_t {
    kWithDriver = 0, // queued, or being handled by the capture thread
    kHeld = 1,       // handed out as a frame
    kReturned = 2,   // released by its holder; the capture thread queues it again
};

constexpr int64_t kNsPerMs = 1'000'000;
constexpr int kMinStallTimeoutMs = 200;
constexpr int kStallPeriods = 5;
// A stall this many stall timeouts long (and at least kMinStallReopenMs) reopens the
// device: a wedged UVC camera often needs it.
constexpr int kStallReopenFactor = 4;
constexpr int64_t kMinStallReopenMs = 1000;
// Extra pool frames for decoded formats beyond the kernel buffers: what a consumer
// (stereo sync) may hold while the camera keeps going.
constexpr std::size_t kExtraPoolFrames = 2;
// Frames behind a camera's fps: about a second at 30 fps, as the replay's pairs.
constexpr std::size_t kFpsFrames = 32;

void wakeUp(int event_fd) noexcept
{
    const uint64_t one = 1;
    // EAGAIN only when the counter is saturated, which already means "awake".
    [[maybe_unused]] const ssize_t n = ::write(event_fd, &one, sizeof one);
}

} // namespace

// One open of the device: the device, its mapped buffers, and one Frame per buffer
// (GREY frames are headers over the buffers). It outlives the open while any of its
// frames is still held, so a holder never reads unmapped memory.
//
// Thread-safety: recycle() from any thread; everything else on the capture thread (or
// the controlling thread while that thread is not running).
class BufferSet final : public FrameRecycler {
  public:
    explicit BufferSet(int wake_fd) : wake_fd_(wake_fd) {}

    // After allocateBuffers(): the frames and their states.
    void attachBuffers(const NegotiatedFormat& format)
    {
        const std::size_t count = device.bufferCount();
        frames.resize(count);
        states = std::make_unique<std::atomic<uint8_t>[]>(count);
        for (std::size_t i = 0; i < count; ++i) {
            states[i].store(kWithDriver, std::memory_order_relaxed);
            frames[i].owner = this;
            if (format.fourcc == V4L2_PIX_FMT_GREY)
                frames[i].image = cv::Mat(format.height, format.width, CV_8UC1,
                                          device.buffer(i).data, format.bytes_per_line);
        }
    }

    void recycle(Frame* frame) noexcept override
    {
        const auto index = static_cast<std::size_t>(frame - frames.data());
        states[index].store(kReturned, std::memory_order_release);
        wakeUp(wake_fd_);
    }

    std::size_t heldCount() const noexcept
    {
        std::size_t held = 0;
        for (std::size_t i = 0; i < frames.size(); ++i)
            held += states[i].load(std::memory_order_acquire) == kHeld ? 1 : 0;
        return held;
    }

    // Stops streaming; buffers not held are no longer with the driver.
    void retire() noexcept
    {
        device.streamOff();
        for (std::size_t i = 0; i < frames.size(); ++i) {
            uint8_t returned = kReturned;
            states[i].compare_exchange_strong(returned, kWithDriver, std::memory_order_acq_rel);
        }
        queued = 0;
    }

    V4l2Device device;
    std::vector<Frame> frames;
    std::unique_ptr<std::atomic<uint8_t>[]> states;
    std::size_t queued = 0; // buffers with the driver (capture thread only)

  private:
    int wake_fd_;
};

class V4l2Camera::Impl {
  public:
    Impl(const CameraSettings& settings, uint32_t index, std::string name)
        : settings_(settings), index_(index), name_(std::move(name))
    {
    }

    ~Impl()
    {
        stop();
        active_.reset();
        retired_.clear();
    }

    int start(CapturedRing& ring, std::atomic<uint32_t>* wake)
    {
        if (thread_.joinable())
            return -EBUSY;
        if (!wake_fd_) {
            wake_fd_.reset(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC));
            if (!wake_fd_) {
                const int error_number = errno;
                setState(SourceState::Failed,
                         fmt::format("{}: eventfd: {}", settings_.device, errnoText(error_number)));
                return -error_number;
            }
        }
        setState(SourceState::Starting, {});
        if (const int rc = openDevice(); rc < 0)
            return rc;
        ring_ = &ring;
        wake_ = wake;
        stop_requested_.store(false, std::memory_order_relaxed);
        setState(SourceState::Running, {});
        thread_ = std::thread([this] { run(); });
        return 0;
    }

    void stop() noexcept
    {
        if (thread_.joinable()) {
            stop_requested_.store(true, std::memory_order_release);
            wakeUp(wake_fd_.get());
            thread_.join();
        }
        if (active_) {
            active_->retire();
            retired_.push_back(std::move(active_));
        }
        collectRetired();
        if (state_.load(std::memory_order_relaxed) != SourceState::Stopped)
            setState(SourceState::Stopped, {});
    }

    V4l2CameraStatus status() const
    {
        V4l2CameraStatus out;
        {
            std::lock_guard lock(status_mutex_);
            out.camera.last_error = last_error_;
            out.format = format_;
            out.controls = controls_;
        }
        out.camera.last_bad_frame = last_bad_frame_.read();
        out.camera.name = name_;
        out.device = settings_.device;
        out.camera.state = state_.load(std::memory_order_acquire);
        out.camera.frames = frames_.load(std::memory_order_relaxed);
        out.camera.dropped = dropped_.load(std::memory_order_relaxed);
        out.camera.bad_frames = bad_frames_.load(std::memory_order_relaxed);
        const int64_t last_ns = last_frame_ns_.load(std::memory_order_relaxed);
        // A camera that stopped delivering has no rate, whatever its last figure said.
        out.camera.fps = (last_ns != 0 && monotonicNowNs() - last_ns < 2'000 * kNsPerMs)
                             ? fps_.perSecond()
                             : 0.0;
        out.kernel_monotonic_stamps = kernel_monotonic_.load(std::memory_order_relaxed);
        out.pool_exhausted = pool_exhausted_.load(std::memory_order_relaxed);
        out.reopens = reopens_.load(std::memory_order_relaxed);
        out.sequence_gaps = sequence_gaps_.load(std::memory_order_relaxed);
        return out;
    }

  private:
    // --- state shared with status() -------------------------------------------------

    void setState(SourceState state, std::string error)
    {
        std::lock_guard lock(status_mutex_);
        state_.store(state, std::memory_order_release);
        last_error_ = std::move(error);
    }

    // --- open / close (start(), then the capture thread) -----------------------------

    int stallTimeoutMs(double fps) const noexcept
    {
        if (settings_.stall_timeout_ms > 0)
            return settings_.stall_timeout_ms;
        const double period_ms = fps > 0.0 ? 1000.0 / fps : 1000.0 / std::max(settings_.fps, 1.0);
        return std::max(kMinStallTimeoutMs, static_cast<int>(kStallPeriods * period_ms));
    }

    // Opens, negotiates, applies controls, maps and queues the buffers, starts
    // streaming. On failure the state is Failed with the reason, and nothing stays open.
    int openDevice()
    {
        auto set = std::make_unique<BufferSet>(wake_fd_.get());
        NegotiatedFormat format;
        std::vector<ControlReading> controls;
        int rc = set->device.open(settings_.device);
        if (rc == 0)
            rc = set->device.negotiate(settings_, format);
        if (rc == 0) {
            controls = set->device.applyControls(settings_.controls, settings_.lock_exposure);
            rc = set->device.allocateBuffers(settings_.buffer_count);
        }
        if (rc == 0) {
            set->attachBuffers(format);
            for (uint32_t i = 0; i < set->device.bufferCount() && rc == 0; ++i)
                rc = set->device.queueBuffer(i);
            set->queued = set->device.bufferCount();
        }
        if (rc == 0)
            rc = set->device.streamOn();
        if (rc < 0) {
            setState(SourceState::Failed, set->device.errorText());
            return rc;
        }

        decoder_ = std::make_unique<FrameDecoder>(format.fourcc, format.width, format.height,
                                                  format.bytes_per_line, format.full_range);
        format.colour = settings_.keep_colour && carriesColour(format.fourcc);
        // Every format but GREY carries colour, so a reopen that negotiates another one
        // needs the same pool (which may not go while frames of it are held).
        if (!decoder_->inPlace() && !pool_)
            pool_ = std::make_unique<FramePool>(set->device.bufferCount() + kExtraPoolFrames,
                                                cv::Size(format.width, format.height), CV_8UC1,
                                                format.colour);
        stall_timeout_ms_ = stallTimeoutMs(format.fps);
        frame_period_ns_ = static_cast<int64_t>(
            1e9 / (format.fps > 0.0 ? format.fps : std::max(settings_.fps, 1.0)));
        empty_since_ns_ = 0;
        have_sequence_ = false;
        sequence_base_ = next_sequence_;
        stream_start_ns_ = monotonicNowNs();
        stalled_ = false;
        exhausted_ = false;
        bad_since_good_ = 0;

        for (const ControlReading& control : controls) {
            if (control.requested && !control.error.empty())
                spdlog::warn("camera {} ({}): control {}: {}", name_, settings_.device,
                             control.name, control.error);
        }
        spdlog::info("camera {} ({}, {}): {} {}x{} @ {:.2f} fps, {} buffers{}; {}", name_,
                     settings_.device, set->device.identity().card, format.format_name,
                     format.width, format.height, format.fps, set->device.bufferCount(),
                     format.colour ? ", colour kept" : "", format.reason);
        {
            std::lock_guard lock(status_mutex_);
            format_ = std::move(format);
            controls_ = std::move(controls);
        }
        active_ = std::move(set);
        return 0;
    }

    // Failure of the open device: retire it (its held frames stay valid) and go Failed.
    void failDevice(std::string reason)
    {
        spdlog::error("camera {}: {}; reopening with backoff", name_, reason);
        active_->retire();
        retired_.push_back(std::move(active_));
        collectRetired();
        setState(SourceState::Failed, std::move(reason));
    }

    // Closes retired opens whose frames have all come back.
    void collectRetired() noexcept
    {
        std::erase_if(retired_,
                      [](const std::unique_ptr<BufferSet>& set) { return set->heldCount() == 0; });
    }

    // --- the capture thread ----------------------------------------------------------

    // Sleeps up to `timeout_ms` or until woken (stop, a returned buffer). Drains the wake
    // counter. Returns false when stop was asked.
    bool waitForWake(int timeout_ms) noexcept
    {
        pollfd fd{wake_fd_.get(), POLLIN, 0};
        ::poll(&fd, 1, std::max(timeout_ms, 0));
        drainWake();
        return !stop_requested_.load(std::memory_order_acquire);
    }

    void drainWake() noexcept
    {
        uint64_t count = 0;
        [[maybe_unused]] const ssize_t n = ::read(wake_fd_.get(), &count, sizeof count);
    }

    void run()
    {
        int backoff_ms = settings_.reopen_min_ms;
        while (!stop_requested_.load(std::memory_order_acquire)) {
            collectRetired();
            if (!active_) {
                if (!waitForWake(backoff_ms))
                    break;
                if (!active_ && openDevice() == 0) {
                    reopens_.fetch_add(1, std::memory_order_relaxed);
                    setState(SourceState::Running, {});
                    backoff_ms = settings_.reopen_min_ms;
                } else {
                    backoff_ms = std::min(backoff_ms * 2, settings_.reopen_max_ms);
                }
                continue;
            }
            captureOnce();
        }
    }

    // One round: queue returned buffers, wait for a frame, take every frame ready.
    void captureOnce()
    {
        BufferSet& set = *active_;
        for (uint32_t i = 0; i < set.frames.size(); ++i) {
            if (set.states[i].load(std::memory_order_acquire) != kReturned)
                continue;
            set.states[i].store(kWithDriver, std::memory_order_relaxed);
            if (const int rc = set.device.queueBuffer(i); rc < 0) {
                failDevice(set.device.errorText());
                return;
            }
            ++set.queued;
        }

        const int64_t now_ns = monotonicNowNs();
        const int64_t last_ns =
            std::max(last_frame_ns_.load(std::memory_order_relaxed), stream_start_ns_);
        const int64_t silent_ms = (now_ns - last_ns) / kNsPerMs;

        if (set.queued == 0) {
            // Every buffer is held by a consumer: nothing can be captured until one comes
            // back. Normal for a moment (the last free buffer waits in the ring); once a
            // frame period has passed, the driver has lost a frame for it.
            if (empty_since_ns_ == 0)
                empty_since_ns_ = now_ns;
            const int64_t empty_ns = now_ns - empty_since_ns_;
            if (!exhausted_ && empty_ns < frame_period_ns_) {
                waitForWake(
                    static_cast<int>((frame_period_ns_ - empty_ns + kNsPerMs - 1) / kNsPerMs));
                return;
            }
            if (!exhausted_) {
                exhausted_ = true;
                pool_exhausted_.fetch_add(1, std::memory_order_relaxed);
                setState(SourceState::Stalled,
                         fmt::format("{}: all {} capture buffers are held by the consumer "
                                     "(pool exhausted)",
                                     settings_.device, set.frames.size()));
                spdlog::warn("camera {}: all {} capture buffers held; waiting for one back", name_,
                             set.frames.size());
            }
            waitForWake(stall_timeout_ms_);
            return;
        }

        empty_since_ns_ = 0;
        if (silent_ms >= stall_timeout_ms_ && !stalled_ && !exhausted_) {
            stalled_ = true;
            const std::string what = silenceText(silent_ms);
            setState(SourceState::Stalled, fmt::format("{}: {} (stall timeout {} ms)",
                                                       settings_.device, what, stall_timeout_ms_));
            spdlog::warn("camera {}: {}", name_, what);
        }
        const int64_t reopen_ms =
            std::max<int64_t>(int64_t{kStallReopenFactor} * stall_timeout_ms_, kMinStallReopenMs);
        if (stalled_ && silent_ms >= reopen_ms) {
            failDevice(fmt::format("{}: {}, reopening", settings_.device, silenceText(silent_ms)));
            return;
        }

        pollfd fds[2] = {{set.device.fd(), POLLIN, 0}, {wake_fd_.get(), POLLIN, 0}};
        const int wait_ms = static_cast<int>(std::clamp<int64_t>(
            (stalled_ ? reopen_ms : stall_timeout_ms_) - silent_ms, 1, stall_timeout_ms_));
        const int ready = ::poll(fds, 2, wait_ms);
        if (ready < 0) {
            if (errno != EINTR)
                failDevice(fmt::format("{}: poll: {}", settings_.device, errnoText(errno)));
            return;
        }
        if ((fds[1].revents & POLLIN) != 0)
            drainWake();
        if (fds[0].revents == 0)
            return;

        // POLLIN: frames are done. POLLERR/POLLHUP: DQBUF tells what went wrong.
        for (;;) {
            DequeuedBuffer buffer;
            const int rc = set.device.dequeueBuffer(buffer);
            if (rc == -EAGAIN) {
                if ((fds[0].revents & (POLLERR | POLLHUP)) != 0 && (fds[0].revents & POLLIN) == 0)
                    failDevice(fmt::format("{}: poll reported an error ({}) but no frame is ready",
                                           settings_.device,
                                           (fds[0].revents & POLLHUP) != 0 ? "hang-up" : "error"));
                return;
            }
            if (rc < 0) {
                // ENODEV: unplugged; EIO: the device or its bus failed; anything else is
                // as fatal for this open.
                failDevice(set.device.errorText());
                return;
            }
            --set.queued;
            if (!handleBuffer(set, buffer)) {
                failDevice(set.device.errorText());
                return;
            }
        }
    }

    // A dequeued buffer: count it, hand it on (or skip it when bad), queue it again when it
    // is not handed out as is. Returns false when the device failed.
    bool handleBuffer(BufferSet& set, const DequeuedBuffer& buffer)
    {
        // Sequence gaps: frames the driver could not deliver (no buffer queued, a bus
        // hiccup). The first frame of a stream starts the count.
        if (have_sequence_ && buffer.sequence > last_v4l2_sequence_ + 1) {
            const uint64_t gap = buffer.sequence - last_v4l2_sequence_ - 1;
            dropped_.fetch_add(gap, std::memory_order_relaxed);
            sequence_gaps_.fetch_add(gap, std::memory_order_relaxed);
        }
        have_sequence_ = true;
        last_v4l2_sequence_ = buffer.sequence;
        const uint64_t sequence = sequence_base_ + buffer.sequence;
        next_sequence_ = sequence + 1;

        const int64_t now_ns = monotonicNowNs();
        int64_t stamp_ns = now_ns;
        if ((buffer.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC) {
            stamp_ns = buffer.timestamp_ns;
            kernel_monotonic_.store(true, std::memory_order_relaxed);
        } else if (!warned_stamps_) {
            warned_stamps_ = true;
            kernel_monotonic_.store(false, std::memory_order_relaxed);
            spdlog::warn("camera {} ({}): the driver's timestamps are not on CLOCK_MONOTONIC "
                         "(flags 0x{:x}); stamping frames at dequeue, which adds the dequeue "
                         "latency to the pairing skew",
                         name_, settings_.device, buffer.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK);
        }

        if ((buffer.flags & V4L2_BUF_FLAG_ERROR) != 0)
            return skipBad(set, buffer.index,
                           "the driver flagged the frame as corrupt (V4L2_BUF_FLAG_ERROR)");

        FrameHandle frame;
        if (decoder_->inPlace()) {
            if (decoder_->checkInPlace(buffer.bytes_used) != DecodeStatus::Ok)
                return skipBad(set, buffer.index, "bytesused smaller than the image");
            set.states[buffer.index].store(kHeld, std::memory_order_relaxed);
            frame = FrameHandle(&set.frames[buffer.index]);
        } else {
            frame = pool_->acquire();
            if (!frame) {
                dropped_.fetch_add(1, std::memory_order_relaxed);
                if (!exhausted_) {
                    exhausted_ = true;
                    pool_exhausted_.fetch_add(1, std::memory_order_relaxed);
                    setState(SourceState::Stalled,
                             fmt::format("{}: all {} frame buffers are held by the consumer "
                                         "(pool exhausted)",
                                         settings_.device, pool_->capacity()));
                }
                return requeue(set, buffer.index);
            }
            const DecodeStatus decoded =
                decoder_->decode(set.device.buffer(buffer.index).data, buffer.bytes_used,
                                 frame->image, frame->colour);
            if (decoded != DecodeStatus::Ok)
                return skipBad(set, buffer.index, decoder_->lastError());
            if (!requeue(set, buffer.index))
                return false;
        }
        frame->stamp_ns = stamp_ns;
        frame->source_stamp_ns = buffer.timestamp_ns;
        frame->sequence = sequence;
        // Counted before it is handed over: a consumer holding a frame finds it in the
        // status (the ring's push publishes the count with the frame).
        frames_.fetch_add(1, std::memory_order_relaxed);
        last_frame_ns_.store(now_ns, std::memory_order_relaxed);
        ring_->push(CapturedFrame{std::move(frame), index_});
        if (wake_ != nullptr) {
            wake_->fetch_add(1, std::memory_order_release);
            wake_->notify_all();
        }

        bad_since_good_ = 0;
        fps_.add(now_ns);
        if (stalled_ || exhausted_ ||
            state_.load(std::memory_order_relaxed) != SourceState::Running) {
            stalled_ = false;
            exhausted_ = false;
            setState(SourceState::Running, {});
        }
        return true;
    }

    bool requeue(BufferSet& set, uint32_t index)
    {
        if (set.device.queueBuffer(index) < 0)
            return false;
        ++set.queued;
        return true;
    }

    // What the camera has not delivered for `silent_ms`: nothing at all, or only frames
    // that were bad (a stream of them is no picture either, but a different fault).
    std::string silenceText(int64_t silent_ms) const
    {
        if (bad_since_good_ == 0)
            return fmt::format("no frame for {} ms", silent_ms);
        return fmt::format("no good frame for {} ms: {} bad (latest: {})", silent_ms,
                           bad_since_good_, last_bad_frame_.read());
    }

    bool skipBad(BufferSet& set, uint32_t index, const char* why)
    {
        ++bad_since_good_;
        bad_frames_.fetch_add(1, std::memory_order_relaxed);
        last_bad_frame_.write(why);
        return requeue(set, index);
    }

    const CameraSettings& settings_;
    const uint32_t index_;
    const std::string name_;

    std::thread thread_;
    std::atomic<bool> stop_requested_{false};
    UniqueFd wake_fd_; // eventfd: stop() and returned buffers
    CapturedRing* ring_ = nullptr;
    std::atomic<uint32_t>* wake_ = nullptr;

    // The capture thread's (the controlling thread's while it is not running).
    std::unique_ptr<BufferSet> active_;
    std::vector<std::unique_ptr<BufferSet>> retired_; // closed opens with frames still held
    std::unique_ptr<FrameDecoder> decoder_;
    std::unique_ptr<FramePool> pool_; // decoded frames (YUYV, MJPEG, RGB24, BGR24)
    int stall_timeout_ms_ = kMinStallTimeoutMs;
    int64_t frame_period_ns_ = 0;
    int64_t empty_since_ns_ = 0; // when the last buffer left the driver; 0: one is queued
    bool have_sequence_ = false;
    uint32_t last_v4l2_sequence_ = 0;
    uint64_t sequence_base_ = 0;
    uint64_t next_sequence_ = 0;
    int64_t stream_start_ns_ = 0;
    bool stalled_ = false;
    uint64_t bad_since_good_ = 0; // bad frames since the last good one
    bool exhausted_ = false;
    bool warned_stamps_ = false;

    // Counters for status(): written by the capture thread, read anywhere.
    std::atomic<SourceState> state_{SourceState::Stopped};
    std::atomic<uint64_t> frames_{0};
    std::atomic<uint64_t> dropped_{0};
    std::atomic<uint64_t> bad_frames_{0};
    std::atomic<uint64_t> pool_exhausted_{0};
    std::atomic<uint64_t> reopens_{0};
    std::atomic<uint64_t> sequence_gaps_{0};
    std::atomic<int64_t> last_frame_ns_{0};
    RateEstimate<kFpsFrames> fps_; // delivered frames
    std::atomic<bool> kernel_monotonic_{false};

    // Written per bad frame, so without a lock (a frame's problem fits in 160 characters).
    LatestText<160> last_bad_frame_;

    // Taken by the capture thread only when the device changes state (opened, failed,
    // stalled), never per frame.
    mutable std::mutex status_mutex_;
    std::string last_error_;               // guarded by status_mutex_
    NegotiatedFormat format_;              // guarded by status_mutex_
    std::vector<ControlReading> controls_; // guarded by status_mutex_
};

V4l2Camera::V4l2Camera(CameraSettings settings, uint32_t index, std::string name)
    : settings_(std::move(settings)), index_(index),
      impl_(std::make_unique<Impl>(settings_, index, std::move(name)))
{
}

V4l2Camera::~V4l2Camera() = default;

int V4l2Camera::start(CapturedRing& ring, std::atomic<uint32_t>* wake)
{
    return impl_->start(ring, wake);
}

void V4l2Camera::stop() noexcept
{
    impl_->stop();
}

V4l2CameraStatus V4l2Camera::status() const
{
    return impl_->status();
}

cv::Size V4l2Camera::frameSize() const noexcept
{
    return {settings_.width, settings_.height};
}

} // namespace stereod
