// One fake V4L2 capture device: the ioctls, the buffer queue (videobuf2 rules) and the
// thread that fills buffers at the frame rate.

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "tests/fake_v4l2/fake_internal.hpp"

namespace stereod::fake {
namespace {

constexpr uint32_t kMinBuffers = 2;
constexpr uint32_t kMaxBuffers = 32; // VIDEO_MAX_FRAME
constexpr uint32_t kTimestampFlags =
    V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_EOF;

int64_t clockNs(clockid_t clock)
{
    timespec ts{};
    clock_gettime(clock, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

template <size_t N> void copyName(uint8_t (&dst)[N], const std::string& src)
{
    std::memset(dst, 0, N);
    std::memcpy(dst, src.data(), std::min(src.size(), N - 1));
}

template <size_t N> void copyName(char (&dst)[N], const std::string& src)
{
    std::memset(dst, 0, N);
    std::memcpy(dst, src.data(), std::min(src.size(), N - 1));
}

v4l2_fract toInterval(double fps)
{
    const double rounded = std::round(fps);
    if (std::fabs(fps - rounded) < 1e-9)
        return {1, static_cast<uint32_t>(rounded)};
    return {1000, static_cast<uint32_t>(std::lround(fps * 1000.0))};
}

const char* formatDescription(uint32_t fourcc)
{
    switch (fourcc) {
    case V4L2_PIX_FMT_GREY:
        return "8-bit Greyscale";
    case V4L2_PIX_FMT_YUYV:
        return "YUYV 4:2:2";
    case V4L2_PIX_FMT_RGB24:
        return "24-bit RGB 8-8-8";
    case V4L2_PIX_FMT_BGR24:
        return "24-bit BGR 8-8-8";
    default:
        return "Motion-JPEG";
    }
}

uint64_t cacheKey(uint32_t fourcc, uint32_t width, uint32_t height)
{
    return (static_cast<uint64_t>(fourcc) << 32) ^ (static_cast<uint64_t>(width) << 16) ^ height;
}

} // namespace

Device::Device(DeviceSpec spec, uint32_t seed, int64_t epoch_ns)
    : spec_(std::move(spec)), epoch_ns_(epoch_ns), rng_(seed)
{
    replug();
}

Device::~Device()
{
    shutdown();
}

bool Device::alive(const OpenFile& file) const
{
    return plugged_ && file.generation == generation_;
}

bool Device::ownsQueue(const OpenFile& file) const
{
    return owner_ == nullptr || owner_ == &file;
}

int Device::attach(const std::shared_ptr<OpenFile>& file)
{
    std::lock_guard lock(mutex_);
    if (!plugged_)
        return -ENOENT;
    file->generation = generation_;
    files_.push_back(file.get());
    updateReadinessLocked();
    return 0;
}

void Device::detach(OpenFile* file)
{
    std::unique_lock lock(mutex_);
    if (owner_ == file) {
        // Closing the queue's owner stops streaming and frees the buffers (vb2_queue_release);
        // buffers still mapped stay valid memory until unmapped.
        streamoffLocked(lock);
        for (Buffer& buffer : buffers_)
            buffer.mapped = 0;
        mappings_.clear();
        freeBuffersLocked();
        owner_ = nullptr;
    }
    files_.erase(std::remove(files_.begin(), files_.end(), file), files_.end());
}

short Device::pollEventsLocked(const OpenFile& file) const
{
    if (!alive(file))
        return POLLERR | POLLHUP;
    if (!streaming_ || owner_ != &file)
        return POLLERR;
    return done_.empty() ? 0 : (POLLIN | POLLRDNORM);
}

void Device::updateReadinessLocked()
{
    for (OpenFile* file : files_) {
        const short events = pollEventsLocked(*file);
        publishEvents(file->fd, events);
        const bool ready = events != 0;
        if (ready && !file->signalled) {
            const uint64_t one = 1;
            if (real::write(file->fd, &one, sizeof one) == sizeof one)
                file->signalled = true;
        } else if (!ready && file->signalled) {
            uint64_t count = 0;
            if (real::read(file->fd, &count, sizeof count) == sizeof count)
                file->signalled = false;
        }
    }
}

const FormatSpec* Device::findFormat(uint32_t fourcc) const
{
    for (const FormatSpec& format : spec_.formats)
        if (format.fourcc == fourcc)
            return &format;
    return nullptr;
}

const SizeSpec* Device::currentSize() const
{
    const FormatSpec* format = findFormat(pixelformat_);
    for (const SizeSpec& size : format->sizes)
        if (size.width == width_ && size.height == height_)
            return &size;
    return &format->sizes.front();
}

// As drivers do: an unknown pixel format becomes the first offered, the size the nearest
// offered one, and the derived fields are filled in.
void Device::adjustFormat(v4l2_pix_format& pix) const
{
    const FormatSpec* format = findFormat(pix.pixelformat);
    if (format == nullptr)
        format = &spec_.formats.front();
    const SizeSpec* best = &format->sizes.front();
    int64_t best_distance = INT64_MAX;
    for (const SizeSpec& size : format->sizes) {
        const int64_t distance = std::llabs(static_cast<int64_t>(size.width) - pix.width) +
                                 std::llabs(static_cast<int64_t>(size.height) - pix.height);
        if (distance < best_distance) {
            best_distance = distance;
            best = &size;
        }
    }
    const uint32_t priv = pix.priv;
    std::memset(&pix, 0, sizeof pix);
    pix.pixelformat = format->fourcc;
    pix.width = best->width;
    pix.height = best->height;
    pix.field = V4L2_FIELD_NONE;
    pix.bytesperline = bytesPerLine(format->fourcc, best->width);
    pix.sizeimage = imageBufferSize(format->fourcc, best->width, best->height);
    pix.colorspace =
        format->fourcc == V4L2_PIX_FMT_MJPEG ? V4L2_COLORSPACE_JPEG : V4L2_COLORSPACE_SRGB;
    pix.priv = priv == V4L2_PIX_FMT_PRIV_MAGIC ? V4L2_PIX_FMT_PRIV_MAGIC : 0;
    // The extended fields, for callers that ask for them: YUYV is full range here, as its
    // luma is exactly COLOR_BGR2GRAY's and its chroma COLOR_BGR2YUV's.
    if (pix.priv == V4L2_PIX_FMT_PRIV_MAGIC && format->fourcc == V4L2_PIX_FMT_YUYV) {
        pix.ycbcr_enc = V4L2_YCBCR_ENC_601;
        pix.quantization = V4L2_QUANTIZATION_FULL_RANGE;
    }
}

const ControlSpec* Device::findControl(uint32_t id) const
{
    for (const ControlSpec& control : spec_.controls)
        if (control.id == id)
            return &control;
    return nullptr;
}

int32_t& Device::controlValue(uint32_t id)
{
    return control_values_[id];
}

uint32_t Device::controlFlags(const ControlSpec& control) const
{
    const auto value = [&](uint32_t id, int32_t fallback) {
        const auto it = control_values_.find(id);
        return it == control_values_.end() ? fallback : it->second;
    };
    if (control.id == V4L2_CID_EXPOSURE_ABSOLUTE &&
        findControl(V4L2_CID_EXPOSURE_AUTO) != nullptr &&
        value(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL) != V4L2_EXPOSURE_MANUAL)
        return V4L2_CTRL_FLAG_INACTIVE;
    if (control.id == V4L2_CID_WHITE_BALANCE_TEMPERATURE &&
        findControl(V4L2_CID_AUTO_WHITE_BALANCE) != nullptr &&
        value(V4L2_CID_AUTO_WHITE_BALANCE, 0) != 0)
        return V4L2_CTRL_FLAG_INACTIVE;
    return 0;
}

// Validates (and with `apply` stores) a control value: integers are clamped and rounded
// to the step, booleans become 0/1, a menu value out of range is ERANGE.
int Device::setControlLocked(uint32_t id, int32_t value, bool apply)
{
    const ControlSpec* control = findControl(id);
    if (control == nullptr)
        return -EINVAL;
    int64_t v = value;
    switch (control->type) {
    case ControlType::Boolean:
        v = v != 0 ? 1 : 0;
        break;
    case ControlType::Menu:
        if (v < control->minimum || v > control->maximum)
            return -ERANGE;
        break;
    case ControlType::Integer: {
        v = std::clamp<int64_t>(v, control->minimum, control->maximum);
        const int64_t offset = v - control->minimum;
        v = control->minimum + (offset + control->step / 2) / control->step * control->step;
        if (v > control->maximum)
            v -= control->step;
        break;
    }
    }
    if (apply)
        controlValue(id) = static_cast<int32_t>(v);
    return 0;
}

int Device::queryCtrl(v4l2_queryctrl& q) const
{
    const uint32_t flags = q.id & (V4L2_CTRL_FLAG_NEXT_CTRL | V4L2_CTRL_FLAG_NEXT_COMPOUND);
    const uint32_t id = q.id & ~(V4L2_CTRL_FLAG_NEXT_CTRL | V4L2_CTRL_FLAG_NEXT_COMPOUND);
    const ControlSpec* control = nullptr;
    if (flags & V4L2_CTRL_FLAG_NEXT_CTRL) {
        for (const ControlSpec& c : spec_.controls)
            if (c.id > id) {
                control = &c;
                break;
            }
    } else if (flags == 0) {
        control = findControl(id);
    }
    if (control == nullptr)
        return -EINVAL;
    std::memset(&q, 0, sizeof q);
    q.id = control->id;
    q.type = control->type == ControlType::Integer   ? V4L2_CTRL_TYPE_INTEGER
             : control->type == ControlType::Boolean ? V4L2_CTRL_TYPE_BOOLEAN
                                                     : V4L2_CTRL_TYPE_MENU;
    copyName(q.name, control->name);
    q.minimum = control->minimum;
    q.maximum = control->maximum;
    q.step = control->step;
    q.default_value = control->default_value;
    q.flags = controlFlags(*control);
    return 0;
}

int Device::queryExtCtrl(v4l2_query_ext_ctrl& q) const
{
    v4l2_queryctrl basic{};
    basic.id = q.id;
    const int rc = queryCtrl(basic);
    if (rc != 0)
        return rc;
    std::memset(&q, 0, sizeof q);
    q.id = basic.id;
    q.type = basic.type;
    std::memcpy(q.name, basic.name, sizeof q.name);
    q.minimum = basic.minimum;
    q.maximum = basic.maximum;
    q.step = static_cast<uint64_t>(basic.step);
    q.default_value = basic.default_value;
    q.flags = basic.flags;
    q.elem_size = sizeof(int32_t);
    q.elems = 1;
    q.nr_of_dims = 0;
    return 0;
}

int Device::extCtrls(unsigned long request, v4l2_ext_controls& ctrls)
{
    if (ctrls.count > 0 && ctrls.controls == nullptr)
        return -EFAULT;
    const bool defaults = ctrls.which == V4L2_CTRL_WHICH_DEF_VAL;
    if (defaults && request != VIDIOC_G_EXT_CTRLS) {
        ctrls.error_idx = ctrls.count;
        return -EINVAL;
    }
    // Validation first, so that a failing S_EXT_CTRLS changes nothing.
    for (uint32_t i = 0; i < ctrls.count; ++i) {
        v4l2_ext_control& c = ctrls.controls[i];
        const int rc = request == VIDIOC_G_EXT_CTRLS ? (findControl(c.id) ? 0 : -EINVAL)
                                                     : setControlLocked(c.id, c.value, false);
        if (rc != 0) {
            ctrls.error_idx = request == VIDIOC_S_EXT_CTRLS ? ctrls.count : i;
            return rc;
        }
    }
    for (uint32_t i = 0; i < ctrls.count; ++i) {
        v4l2_ext_control& c = ctrls.controls[i];
        if (request == VIDIOC_G_EXT_CTRLS)
            c.value = defaults ? findControl(c.id)->default_value : controlValue(c.id);
        else if (request == VIDIOC_S_EXT_CTRLS) {
            setControlLocked(c.id, c.value, true);
            c.value = controlValue(c.id);
        }
    }
    return 0;
}

int Device::reqbufs(OpenFile& file, v4l2_requestbuffers& req)
{
    if (req.type != V4L2_BUF_TYPE_VIDEO_CAPTURE || req.memory != V4L2_MEMORY_MMAP)
        return -EINVAL;
    if (!ownsQueue(file) || streaming_)
        return -EBUSY;
    for (const Buffer& buffer : buffers_)
        if (buffer.mapped > 0)
            return -EBUSY;
    freeBuffersLocked();
    req.capabilities = V4L2_BUF_CAP_SUPPORTS_MMAP;
    if (req.count == 0) {
        owner_ = nullptr;
        return 0;
    }
    const uint32_t count = std::clamp(req.count, kMinBuffers, kMaxBuffers);
    const uint32_t page = static_cast<uint32_t>(sysconf(_SC_PAGESIZE));
    size_image_ = imageBufferSize(pixelformat_, width_, height_);
    buffer_stride_ = (size_image_ + page - 1) / page * page;
    memory_bytes_ = static_cast<size_t>(buffer_stride_) * count;
    memfd_ = memfd_create("stereod-fake-v4l2", MFD_CLOEXEC);
    if (memfd_ < 0)
        return -errno;
    if (ftruncate(memfd_, static_cast<off_t>(memory_bytes_)) != 0) {
        const int error = errno;
        freeBuffersLocked();
        return -error;
    }
    void* memory =
        real::mmap(nullptr, memory_bytes_, PROT_READ | PROT_WRITE, MAP_SHARED, memfd_, 0);
    if (memory == MAP_FAILED) {
        const int error = errno;
        freeBuffersLocked();
        return -error;
    }
    memory_ = static_cast<uint8_t*>(memory);
    buffers_.assign(count, Buffer{});
    owner_ = &file;
    req.count = count;
    return 0;
}

void Device::freeBuffersLocked()
{
    if (memory_ != nullptr)
        real::munmap(memory_, memory_bytes_);
    if (memfd_ >= 0)
        real::close(memfd_);
    memory_ = nullptr;
    memfd_ = -1;
    memory_bytes_ = 0;
    buffers_.clear();
    queued_.clear();
    done_.clear();
}

void Device::fillBuffer(uint32_t index, v4l2_buffer& buf) const
{
    const Buffer& b = buffers_[index];
    buf.index = index;
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.field = V4L2_FIELD_NONE;
    buf.bytesused =
        b.state == BufferState::Done || b.state == BufferState::Dequeued ? b.bytesused : 0;
    buf.flags =
        (spec_.monotonic_stamps ? kTimestampFlags
                                : V4L2_BUF_FLAG_TIMESTAMP_UNKNOWN | V4L2_BUF_FLAG_TSTAMP_SRC_EOF);
    if (b.mapped > 0)
        buf.flags |= V4L2_BUF_FLAG_MAPPED;
    if (b.state == BufferState::Queued || b.state == BufferState::Active)
        buf.flags |= V4L2_BUF_FLAG_QUEUED;
    if (b.state == BufferState::Done)
        buf.flags |= V4L2_BUF_FLAG_DONE | (b.flags & V4L2_BUF_FLAG_ERROR);
    buf.timestamp = b.timestamp;
    buf.sequence = b.sequence;
    buf.m.offset = index * buffer_stride_;
    buf.length = size_image_;
}

int Device::qbuf(OpenFile& file, v4l2_buffer& buf)
{
    if (buf.type != V4L2_BUF_TYPE_VIDEO_CAPTURE || buf.memory != V4L2_MEMORY_MMAP)
        return -EINVAL;
    if (!ownsQueue(file))
        return -EBUSY;
    if (buf.index >= buffers_.size() || buffers_[buf.index].state != BufferState::Dequeued)
        return -EINVAL;
    Buffer& b = buffers_[buf.index];
    b.state = BufferState::Queued;
    b.flags = 0;
    queued_.push_back(buf.index);
    fillBuffer(buf.index, buf);
    return 0;
}

int Device::dqbuf(OpenFile& file, std::unique_lock<std::mutex>& lock, v4l2_buffer& buf)
{
    if (buf.type != V4L2_BUF_TYPE_VIDEO_CAPTURE || buf.memory != V4L2_MEMORY_MMAP)
        return -EINVAL;
    if (!ownsQueue(file))
        return -EBUSY;
    const bool nonblocking = (fcntl(file.fd, F_GETFL) & O_NONBLOCK) != 0;
    for (;;) {
        if (!alive(file))
            return -ENODEV;
        if (!streaming_)
            return -EINVAL;
        if (!done_.empty())
            break;
        if (nonblocking)
            return -EAGAIN;
        cv_.wait(lock);
    }
    const uint32_t index = done_.front();
    done_.pop_front();
    fillBuffer(index, buf);
    buffers_[index].state = BufferState::Dequeued;
    updateReadinessLocked();
    return 0;
}

int Device::streamon(OpenFile& file)
{
    if (!ownsQueue(file))
        return -EBUSY;
    if (buffers_.empty())
        return -EINVAL;
    if (streaming_)
        return 0;
    const uint64_t key = cacheKey(pixelformat_, width_, height_);
    auto it = frame_cache_.find(key);
    if (it == frame_cache_.end()) {
        Passthrough passthrough;
        try {
            it = frame_cache_
                     .emplace(key, renderFrames(spec_.image_files, pixelformat_, width_, height_,
                                                spec_.jpeg_quality))
                     .first;
        } catch (const std::exception&) {
            return -EIO;
        }
    }
    frames_ = &it->second;
    sequence_ = 0;
    streaming_ = true;
    stop_producer_ = false;
    producer_ = std::thread([this] { produce(); });
    updateReadinessLocked();
    return 0;
}

void Device::streamoffLocked(std::unique_lock<std::mutex>& lock)
{
    stop_producer_ = true;
    cv_.notify_all();
    std::thread producer = std::move(producer_);
    if (producer.joinable()) {
        lock.unlock();
        producer.join();
        lock.lock();
    }
    streaming_ = false;
    queued_.clear();
    done_.clear();
    for (Buffer& buffer : buffers_)
        buffer.state = BufferState::Dequeued;
    updateReadinessLocked();
    cv_.notify_all();
}

int64_t Device::reportedStampNs(int64_t monotonic_ns) const
{
    if (!spec_.monotonic_stamps)
        return clockNs(CLOCK_REALTIME) + static_cast<int64_t>(spec_.clock_offset_ms * 1e6);
    const double skew = spec_.clock_skew_ppm * 1e-6 * static_cast<double>(monotonic_ns - epoch_ns_);
    return monotonic_ns + static_cast<int64_t>(spec_.clock_offset_ms * 1e6 + skew);
}

// The producer: one frame per period on the grid k*period + phase (CLOCK_MONOTONIC),
// moved by the jitter; a period without a queued buffer loses its frame (a gap in the
// sequence numbers), as a driver does.
void Device::produce()
{
    // Named so that measurements can tell the fake's work (the "DMA") from ours.
    pthread_setname_np(pthread_self(), "fake-v4l2");
    std::unique_lock lock(mutex_);
    const int64_t period_ns = static_cast<int64_t>(1e9 / fps_);
    const int64_t phase_ns = static_cast<int64_t>(spec_.phase_ms * 1e6);
    const auto nextIndex = [&](int64_t now_ns) { return (now_ns - phase_ns) / period_ns + 1; };
    int64_t k = nextIndex(clockNs(CLOCK_MONOTONIC));
    std::uniform_real_distribution<double> jitter(-spec_.jitter_ms, spec_.jitter_ms);
    while (!stop_producer_ && plugged_) {
        const int64_t due_ns =
            k * period_ns + phase_ns +
            (spec_.jitter_ms > 0.0 ? static_cast<int64_t>(jitter(rng_) * 1e6) : 0);
        const std::chrono::steady_clock::time_point due{std::chrono::nanoseconds(due_ns)};
        cv_.wait_until(lock, due, [&] { return stop_producer_ || !plugged_; });
        if (stop_producer_ || !plugged_)
            break;
        int64_t now_ns = clockNs(CLOCK_MONOTONIC);
        if (now_ns < stall_until_ns_) {
            // stall() notifies, so a new (or ended) stall takes effect at once.
            while (!stop_producer_ && plugged_ && clockNs(CLOCK_MONOTONIC) < stall_until_ns_)
                cv_.wait_until(lock, std::chrono::steady_clock::time_point{
                                         std::chrono::nanoseconds(stall_until_ns_)});
            k = nextIndex(clockNs(CLOCK_MONOTONIC));
            continue;
        }
        // Periods that passed while this thread was late were captured and lost.
        const int64_t behind = nextIndex(now_ns) - 1 - k;
        if (behind > 0) {
            sequence_ += static_cast<uint64_t>(behind);
            frames_lost_ += static_cast<uint64_t>(behind);
            k += behind;
        }
        ++k;
        const uint64_t sequence = sequence_++;
        bool lost = queued_.empty();
        if (spec_.drop_every > 0 && (sequence + 1) % spec_.drop_every == 0)
            lost = true;
        if (!lost && drop_pending_ > 0) {
            --drop_pending_;
            lost = true;
        }
        if (lost) {
            ++frames_lost_;
            continue;
        }
        const uint32_t index = queued_.front();
        queued_.pop_front();
        buffers_[index].state = BufferState::Active;
        const std::vector<uint8_t>& frame = (*frames_)[sequence % frames_->size()];
        uint32_t bytes = static_cast<uint32_t>(frame.size());
        uint32_t copy_bytes = bytes;
        uint32_t flags = 0;
        if (corrupt_pending_ > 0) {
            --corrupt_pending_;
            switch (corrupt_kind_) {
            case CorruptKind::Truncated:
                bytes = copy_bytes = bytes / 3;
                break;
            case CorruptKind::BytesUsed:
                bytes = bytes / 2;
                break;
            case CorruptKind::Error:
                flags = V4L2_BUF_FLAG_ERROR;
                break;
            }
        }
        uint8_t* dst = memory_ + static_cast<size_t>(index) * buffer_stride_;
        lock.unlock();
        std::memcpy(dst, frame.data(), copy_bytes);
        if (copy_bytes < frame.size())
            std::memset(dst + copy_bytes, 0, frame.size() - copy_bytes);
        lock.lock();
        Buffer& b = buffers_[index];
        // Stamped with the capture instant, as a driver stamps in its interrupt handler:
        // this thread's own scheduling delay shows as delivery latency, not as jitter.
        const int64_t stamp_ns = reportedStampNs(due_ns);
        b.timestamp.tv_sec = stamp_ns / 1'000'000'000;
        b.timestamp.tv_usec = (stamp_ns % 1'000'000'000) / 1000;
        b.sequence = static_cast<uint32_t>(sequence);
        b.bytesused = bytes;
        b.flags = flags;
        b.state = BufferState::Done;
        done_.push_back(index);
        ++frames_done_;
        updateReadinessLocked();
        cv_.notify_all();
    }
}

int Device::ioctl(OpenFile& file, unsigned long request, void* arg)
{
    std::unique_lock lock(mutex_);
    if (!alive(file))
        return -ENODEV;
    if (arg == nullptr)
        return -EFAULT;
    switch (request) {
    case VIDIOC_QUERYCAP: {
        auto& cap = *static_cast<v4l2_capability*>(arg);
        std::memset(&cap, 0, sizeof cap);
        copyName(cap.driver, spec_.driver);
        copyName(cap.card, spec_.card);
        copyName(cap.bus_info, spec_.bus_info);
        cap.version = (6U << 16) | (1U << 8);
        cap.device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING | V4L2_CAP_EXT_PIX_FORMAT;
        cap.capabilities = cap.device_caps | V4L2_CAP_DEVICE_CAPS;
        return 0;
    }
    case VIDIOC_ENUM_FMT: {
        auto& f = *static_cast<v4l2_fmtdesc*>(arg);
        if (f.type != V4L2_BUF_TYPE_VIDEO_CAPTURE || f.index >= spec_.formats.size())
            return -EINVAL;
        const uint32_t index = f.index;
        std::memset(&f, 0, sizeof f);
        f.index = index;
        f.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        f.pixelformat = spec_.formats[index].fourcc;
        f.flags = f.pixelformat == V4L2_PIX_FMT_MJPEG ? V4L2_FMT_FLAG_COMPRESSED : 0;
        copyName(f.description, formatDescription(f.pixelformat));
        return 0;
    }
    case VIDIOC_ENUM_FRAMESIZES: {
        auto& s = *static_cast<v4l2_frmsizeenum*>(arg);
        const FormatSpec* format = findFormat(s.pixel_format);
        if (format == nullptr || s.index >= format->sizes.size())
            return -EINVAL;
        s.type = V4L2_FRMSIZE_TYPE_DISCRETE;
        s.discrete.width = format->sizes[s.index].width;
        s.discrete.height = format->sizes[s.index].height;
        return 0;
    }
    case VIDIOC_ENUM_FRAMEINTERVALS: {
        auto& fi = *static_cast<v4l2_frmivalenum*>(arg);
        const FormatSpec* format = findFormat(fi.pixel_format);
        if (format == nullptr)
            return -EINVAL;
        for (const SizeSpec& size : format->sizes) {
            if (size.width != fi.width || size.height != fi.height)
                continue;
            if (fi.index >= size.fps.size())
                return -EINVAL;
            fi.type = V4L2_FRMIVAL_TYPE_DISCRETE;
            fi.discrete = toInterval(size.fps[fi.index]);
            return 0;
        }
        return -EINVAL;
    }
    case VIDIOC_G_FMT:
    case VIDIOC_TRY_FMT:
    case VIDIOC_S_FMT: {
        auto& f = *static_cast<v4l2_format*>(arg);
        if (f.type != V4L2_BUF_TYPE_VIDEO_CAPTURE)
            return -EINVAL;
        if (request == VIDIOC_G_FMT) {
            f.fmt.pix.pixelformat = pixelformat_;
            f.fmt.pix.width = width_;
            f.fmt.pix.height = height_;
        }
        if (request == VIDIOC_S_FMT && (!buffers_.empty() || streaming_))
            return -EBUSY;
        adjustFormat(f.fmt.pix);
        if (request == VIDIOC_S_FMT) {
            pixelformat_ = f.fmt.pix.pixelformat;
            width_ = f.fmt.pix.width;
            height_ = f.fmt.pix.height;
            const SizeSpec* size = currentSize();
            if (std::find(size->fps.begin(), size->fps.end(), fps_) == size->fps.end())
                fps_ = size->fps.front();
        }
        return 0;
    }
    case VIDIOC_G_PARM:
    case VIDIOC_S_PARM: {
        auto& p = *static_cast<v4l2_streamparm*>(arg);
        if (p.type != V4L2_BUF_TYPE_VIDEO_CAPTURE)
            return -EINVAL;
        if (request == VIDIOC_S_PARM) {
            if (streaming_)
                return -EBUSY;
            const SizeSpec* size = currentSize();
            const v4l2_fract asked = p.parm.capture.timeperframe;
            double fps = size->fps.front();
            if (asked.numerator != 0 && asked.denominator != 0) {
                const double want = static_cast<double>(asked.denominator) / asked.numerator;
                for (double offered : size->fps)
                    if (std::fabs(offered - want) < std::fabs(fps - want))
                        fps = offered;
            }
            fps_ = fps;
        }
        std::memset(&p.parm, 0, sizeof p.parm);
        p.parm.capture.capability = V4L2_CAP_TIMEPERFRAME;
        p.parm.capture.timeperframe = toInterval(fps_);
        return 0;
    }
    case VIDIOC_QUERYCTRL:
        return queryCtrl(*static_cast<v4l2_queryctrl*>(arg));
    case VIDIOC_QUERY_EXT_CTRL:
        return queryExtCtrl(*static_cast<v4l2_query_ext_ctrl*>(arg));
    case VIDIOC_QUERYMENU: {
        auto& m = *static_cast<v4l2_querymenu*>(arg);
        const ControlSpec* control = findControl(m.id);
        if (control == nullptr || control->type != ControlType::Menu ||
            m.index < static_cast<uint32_t>(control->minimum) ||
            m.index > static_cast<uint32_t>(control->maximum))
            return -EINVAL;
        // v4l2_querymenu is packed: copy into a local buffer first.
        uint8_t name[sizeof m.name];
        copyName(name, control->menu[m.index]);
        std::memcpy(m.name, name, sizeof name);
        m.reserved = 0;
        return 0;
    }
    case VIDIOC_G_CTRL: {
        auto& c = *static_cast<v4l2_control*>(arg);
        if (findControl(c.id) == nullptr)
            return -EINVAL;
        c.value = controlValue(c.id);
        return 0;
    }
    case VIDIOC_S_CTRL: {
        auto& c = *static_cast<v4l2_control*>(arg);
        const int rc = setControlLocked(c.id, c.value, true);
        if (rc == 0)
            c.value = controlValue(c.id);
        return rc;
    }
    case VIDIOC_G_EXT_CTRLS:
    case VIDIOC_S_EXT_CTRLS:
    case VIDIOC_TRY_EXT_CTRLS:
        return extCtrls(request, *static_cast<v4l2_ext_controls*>(arg));
    case VIDIOC_ENUMINPUT: {
        auto& input = *static_cast<v4l2_input*>(arg);
        if (input.index != 0)
            return -EINVAL;
        std::memset(&input, 0, sizeof input);
        copyName(input.name, "Camera 1");
        input.type = V4L2_INPUT_TYPE_CAMERA;
        return 0;
    }
    case VIDIOC_G_INPUT:
        *static_cast<int*>(arg) = 0;
        return 0;
    case VIDIOC_S_INPUT:
        return *static_cast<int*>(arg) == 0 ? 0 : -EINVAL;
    case VIDIOC_REQBUFS:
        return reqbufs(file, *static_cast<v4l2_requestbuffers*>(arg));
    case VIDIOC_QUERYBUF: {
        auto& buf = *static_cast<v4l2_buffer*>(arg);
        if (buf.type != V4L2_BUF_TYPE_VIDEO_CAPTURE || buf.index >= buffers_.size())
            return -EINVAL;
        fillBuffer(buf.index, buf);
        return 0;
    }
    case VIDIOC_QBUF:
        return qbuf(file, *static_cast<v4l2_buffer*>(arg));
    case VIDIOC_DQBUF:
        return dqbuf(file, lock, *static_cast<v4l2_buffer*>(arg));
    case VIDIOC_STREAMON:
    case VIDIOC_STREAMOFF: {
        if (*static_cast<int*>(arg) != V4L2_BUF_TYPE_VIDEO_CAPTURE)
            return -EINVAL;
        if (request == VIDIOC_STREAMON)
            return streamon(file);
        if (!ownsQueue(file))
            return -EBUSY;
        streamoffLocked(lock);
        return 0;
    }
    default:
        return -ENOTTY;
    }
}

void* Device::mmap(OpenFile& file, void* addr, size_t length, int prot, int flags, off_t offset,
                   int* error)
{
    std::lock_guard lock(mutex_);
    if (!alive(file)) {
        *error = ENODEV;
        return nullptr;
    }
    // vb2_mmap: shared mappings only, of one whole buffer at its offset.
    if ((flags & MAP_SHARED) == 0 || (prot & PROT_READ) == 0 || buffer_stride_ == 0 || offset < 0 ||
        offset % buffer_stride_ != 0 ||
        static_cast<size_t>(offset / buffer_stride_) >= buffers_.size() || length == 0 ||
        length > buffer_stride_) {
        *error = EINVAL;
        return nullptr;
    }
    void* mapped = real::mmap(addr, length, prot, flags, memfd_, offset);
    if (mapped == MAP_FAILED) {
        *error = errno;
        return nullptr;
    }
    const int index = static_cast<int>(offset / buffer_stride_);
    ++buffers_[static_cast<size_t>(index)].mapped;
    mappings_.push_back({mapped, index});
    return mapped;
}

bool Device::unmapped(void* addr)
{
    std::lock_guard lock(mutex_);
    for (auto it = mappings_.begin(); it != mappings_.end(); ++it) {
        if (it->addr != addr)
            continue;
        --buffers_[static_cast<size_t>(it->buffer)].mapped;
        mappings_.erase(it);
        return true;
    }
    return false;
}

void Device::unplug()
{
    std::unique_lock lock(mutex_);
    if (!plugged_)
        return;
    plugged_ = false;
    ++generation_;
    streamoffLocked(lock);
    mappings_.clear();
    freeBuffersLocked();
    owner_ = nullptr;
    updateReadinessLocked();
    cv_.notify_all();
}

// A device comes back as a fresh one: default format, rate and controls.
void Device::replug()
{
    std::lock_guard lock(mutex_);
    plugged_ = true;
    const FormatSpec& format = spec_.formats.front();
    pixelformat_ = format.fourcc;
    width_ = format.sizes.front().width;
    height_ = format.sizes.front().height;
    fps_ = format.sizes.front().fps.front();
    control_values_.clear();
    for (const ControlSpec& control : spec_.controls)
        control_values_[control.id] = control.default_value;
    stall_until_ns_ = 0;
    drop_pending_ = 0;
    corrupt_pending_ = 0;
}

void Device::stall(int64_t ms)
{
    std::lock_guard lock(mutex_);
    stall_until_ns_ = clockNs(CLOCK_MONOTONIC) + ms * 1'000'000;
    cv_.notify_all();
}

void Device::drop(uint32_t frames)
{
    std::lock_guard lock(mutex_);
    drop_pending_ += frames;
}

void Device::corrupt(uint32_t frames, CorruptKind kind)
{
    std::lock_guard lock(mutex_);
    corrupt_pending_ = frames;
    corrupt_kind_ = kind;
}

void Device::shutdown()
{
    unplug();
}

StereodFakeV4l2Stats Device::stats()
{
    std::lock_guard lock(mutex_);
    StereodFakeV4l2Stats s{};
    s.frames_done = frames_done_;
    s.frames_lost = frames_lost_;
    s.next_sequence = sequence_;
    s.open_fds = static_cast<int32_t>(files_.size());
    s.buffers = static_cast<int32_t>(buffers_.size());
    for (const Buffer& b : buffers_) {
        s.buffers_mapped += b.mapped;
        if (b.state != BufferState::Dequeued)
            ++s.buffers_queued;
    }
    s.streaming = streaming_ ? 1 : 0;
    s.plugged = plugged_ ? 1 : 0;
    s.width = width_;
    s.height = height_;
    s.pixelformat = pixelformat_;
    s.fps = fps_;
    return s;
}

} // namespace stereod::fake
