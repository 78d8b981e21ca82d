#include "capture/v4l2_device.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <utility>

#include <fcntl.h>
#include <fmt/format.h>
#include <libv4l2.h>
#include <sys/mman.h>

#include "base/system_error.hpp"
#include "base/unique_fd.hpp"

namespace stereod {

namespace {

double intervalToFps(const v4l2_fract& interval) noexcept
{
    return interval.numerator == 0 ? 0.0
                                   : static_cast<double>(interval.denominator) / interval.numerator;
}

// 30 -> 1/30; 29.97 -> 1000/29970: drivers expect the simplest fraction for whole rates.
v4l2_fract fpsToInterval(double fps) noexcept
{
    v4l2_fract interval{};
    if (std::abs(fps - std::round(fps)) < 1e-6) {
        interval.numerator = 1;
        interval.denominator = static_cast<uint32_t>(std::lround(fps));
    } else {
        interval.numerator = 1000;
        interval.denominator = static_cast<uint32_t>(std::lround(fps * 1000.0));
    }
    return interval;
}

std::string fixedText(const uint8_t* text, std::size_t size)
{
    const auto* chars = reinterpret_cast<const char*>(text);
    return std::string(chars, strnlen(chars, size));
}

} // namespace

V4l2Device::~V4l2Device()
{
    close();
}

V4l2Device::V4l2Device(V4l2Device&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)), streaming_(std::exchange(other.streaming_, false)),
      path_(std::move(other.path_)), identity_(std::move(other.identity_)),
      buffers_(std::move(other.buffers_)), error_(std::move(other.error_))
{
    other.buffers_.clear();
}

V4l2Device& V4l2Device::operator=(V4l2Device&& other) noexcept
{
    if (this != &other) {
        close();
        fd_ = std::exchange(other.fd_, -1);
        streaming_ = std::exchange(other.streaming_, false);
        path_ = std::move(other.path_);
        identity_ = std::move(other.identity_);
        buffers_ = std::move(other.buffers_);
        other.buffers_.clear();
        error_ = std::move(other.error_);
    }
    return *this;
}

int V4l2Device::fail(const char* what, int error_number)
{
    error_ = fmt::format("{} on {}: {}", what, path_, errnoText(error_number));
    return -error_number;
}

int V4l2Device::xioctl(unsigned long request, void* arg)
{
    int result = 0;
    do {
        result = v4l2_ioctl(fd_, request, arg);
    } while (result < 0 && errno == EINTR);
    return result < 0 ? -errno : 0;
}

int V4l2Device::open(const std::string& path)
{
    close();
    path_ = path;
    error_.clear();
    UniqueFd fd(::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC));
    if (!fd)
        return fail("open", errno);
    // See the header: no libv4l2 format emulation, we want the camera's own formats.
    if (v4l2_fd_open(fd.get(), V4L2_DISABLE_CONVERSION) < 0)
        return fail("v4l2_fd_open", errno);
    // From here libv4l2 owns the descriptor: close() gives it back with v4l2_close().
    fd_ = fd.release();

    v4l2_capability caps{};
    if (const int rc = xioctl(VIDIOC_QUERYCAP, &caps); rc < 0) {
        const int result = fail("VIDIOC_QUERYCAP (not a V4L2 device?)", -rc);
        close();
        return result;
    }
    identity_.driver = fixedText(caps.driver, sizeof caps.driver);
    identity_.card = fixedText(caps.card, sizeof caps.card);
    identity_.bus_info = fixedText(caps.bus_info, sizeof caps.bus_info);
    identity_.device_caps =
        (caps.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? caps.device_caps : caps.capabilities;
    if ((identity_.device_caps & V4L2_CAP_VIDEO_CAPTURE) == 0 ||
        (identity_.device_caps & V4L2_CAP_STREAMING) == 0) {
        error_ = fmt::format("{} ({}, driver {}) is not a video capture device with streaming I/O",
                             path_, identity_.card, identity_.driver);
        close();
        return -ENODEV;
    }
    return 0;
}

void V4l2Device::close() noexcept
{
    if (fd_ < 0)
        return;
    streamOff();
    releaseBuffers();
    v4l2_close(fd_);
    fd_ = -1;
}

int V4l2Device::enumerateFormats(std::vector<FormatDescription>& formats)
{
    formats.clear();
    for (uint32_t i = 0;; ++i) {
        v4l2_fmtdesc desc{};
        desc.index = i;
        desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        const int rc = xioctl(VIDIOC_ENUM_FMT, &desc);
        if (rc == -EINVAL)
            break;
        if (rc < 0)
            return fail("VIDIOC_ENUM_FMT", -rc);
        if ((desc.flags & V4L2_FMT_FLAG_EMULATED) != 0)
            continue;
        FormatDescription format;
        format.fourcc = desc.pixelformat;
        format.name = fourccName(desc.pixelformat);
        format.description = fixedText(desc.description, sizeof desc.description);
        format.compressed = (desc.flags & V4L2_FMT_FLAG_COMPRESSED) != 0;

        for (uint32_t s = 0;; ++s) {
            v4l2_frmsizeenum frame_size{};
            frame_size.index = s;
            frame_size.pixel_format = desc.pixelformat;
            if (xioctl(VIDIOC_ENUM_FRAMESIZES, &frame_size) < 0)
                break; // EINVAL ends the list; a driver without the ioctl lists none
            FrameSizeDescription size;
            if (frame_size.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
                size.width = static_cast<int>(frame_size.discrete.width);
                size.height = static_cast<int>(frame_size.discrete.height);
            } else {
                const v4l2_frmsize_stepwise& range = frame_size.stepwise;
                size.width = static_cast<int>(range.min_width);
                size.height = static_cast<int>(range.min_height);
                size.max_width = static_cast<int>(range.max_width);
                size.max_height = static_cast<int>(range.max_height);
                size.step_width = static_cast<int>(range.step_width);
                size.step_height = static_cast<int>(range.step_height);
            }
            // Rates at this size (for a range of sizes: at its largest).
            for (uint32_t r = 0;; ++r) {
                v4l2_frmivalenum interval{};
                interval.index = r;
                interval.pixel_format = desc.pixelformat;
                interval.width =
                    static_cast<uint32_t>(size.isRange() ? size.max_width : size.width);
                interval.height =
                    static_cast<uint32_t>(size.isRange() ? size.max_height : size.height);
                if (xioctl(VIDIOC_ENUM_FRAMEINTERVALS, &interval) < 0)
                    break;
                if (interval.type == V4L2_FRMIVAL_TYPE_DISCRETE) {
                    size.fps.push_back(intervalToFps(interval.discrete));
                } else {
                    // The longest interval is the slowest rate.
                    size.min_fps = intervalToFps(interval.stepwise.max);
                    size.max_fps = intervalToFps(interval.stepwise.min);
                    break;
                }
            }
            std::sort(size.fps.begin(), size.fps.end(), std::greater<>());
            format.sizes.push_back(std::move(size));
            if (frame_size.type != V4L2_FRMSIZE_TYPE_DISCRETE)
                break;
        }
        formats.push_back(std::move(format));
    }
    return 0;
}

int V4l2Device::negotiate(const CameraSettings& settings, NegotiatedFormat& out)
{
    std::vector<FormatDescription> formats;
    if (const int rc = enumerateFormats(formats); rc < 0)
        return rc;

    const bool is_auto = settings.format == PixelFormatChoice::Auto;
    const FormatChoice choice = chooseFormat(formats, settings);
    if (choice.format == nullptr) {
        error_ = fmt::format("{} ({}) {}", path_, identity_.card, choice.refusal);
        return -EINVAL;
    }
    const FormatDescription* chosen = choice.format;
    const std::string& passed_over = choice.passed_over;

    v4l2_format format{};
    format.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    format.fmt.pix.pixelformat = chosen->fourcc;
    format.fmt.pix.width = static_cast<uint32_t>(settings.width);
    format.fmt.pix.height = static_cast<uint32_t>(settings.height);
    format.fmt.pix.field = V4L2_FIELD_NONE;
    // The extended fields (quantization: how to turn YUYV into colour) are filled in only
    // when asked for.
    format.fmt.pix.priv = V4L2_PIX_FMT_PRIV_MAGIC;
    if (const int rc = xioctl(VIDIOC_S_FMT, &format); rc < 0)
        return fail("VIDIOC_S_FMT", -rc);
    if (format.fmt.pix.pixelformat != chosen->fourcc ||
        format.fmt.pix.width != static_cast<uint32_t>(settings.width) ||
        format.fmt.pix.height != static_cast<uint32_t>(settings.height)) {
        error_ = fmt::format("{} ({}): asked {} {}x{}, the driver set {} {}x{}; it offers: {}",
                             path_, identity_.card, chosen->name, settings.width, settings.height,
                             fourccName(format.fmt.pix.pixelformat), format.fmt.pix.width,
                             format.fmt.pix.height, describeFormat(*chosen));
        return -EINVAL;
    }
    const uint32_t min_line = bytesPerPixel(chosen->fourcc) * format.fmt.pix.width;
    if (chosen->fourcc != V4L2_PIX_FMT_MJPEG &&
        (format.fmt.pix.bytesperline < min_line ||
         format.fmt.pix.sizeimage < format.fmt.pix.bytesperline * format.fmt.pix.height)) {
        error_ = fmt::format("{}: driver set bytesperline {} and sizeimage {} for {} {}x{}", path_,
                             format.fmt.pix.bytesperline, format.fmt.pix.sizeimage, chosen->name,
                             settings.width, settings.height);
        return -EINVAL;
    }

    out = NegotiatedFormat{};
    out.fourcc = chosen->fourcc;
    out.format_name = chosen->name;
    out.width = settings.width;
    out.height = settings.height;
    out.bytes_per_line = chosen->fourcc == V4L2_PIX_FMT_MJPEG ? 0 : format.fmt.pix.bytesperline;
    out.size_image = format.fmt.pix.sizeimage;
    const bool extended = format.fmt.pix.priv == V4L2_PIX_FMT_PRIV_MAGIC;
    out.full_range = format.fmt.pix.colorspace == V4L2_COLORSPACE_JPEG ||
                     (extended && format.fmt.pix.quantization == V4L2_QUANTIZATION_FULL_RANGE);

    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    parm.parm.capture.timeperframe = fpsToInterval(settings.fps);
    std::string rate_note;
    if (const int rc = xioctl(VIDIOC_S_PARM, &parm); rc < 0) {
        rate_note = fmt::format(", frame rate not settable ({})", errnoText(-rc));
        parm = v4l2_streamparm{};
        parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        if (xioctl(VIDIOC_G_PARM, &parm) < 0)
            parm.parm.capture.timeperframe = v4l2_fract{};
    } else if ((parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME) == 0) {
        rate_note = ", the driver does not set the frame rate";
    }
    out.fps = intervalToFps(parm.parm.capture.timeperframe);
    if (out.fps > 0.0 && !sameRate(out.fps, settings.fps))
        rate_note += fmt::format(", driver set {} fps instead of {}", formatRate(out.fps),
                                 formatRate(settings.fps));

    if (is_auto) {
        out.reason =
            fmt::format("auto chose {} at {}x{} @ {} fps (preference GREY > YUYV > MJPG > "
                        "RGB3 > BGR3: {}){}{}",
                        chosen->name, settings.width, settings.height, formatRate(settings.fps),
                        chosen->fourcc == V4L2_PIX_FMT_GREY    ? "no conversion, no copy"
                        : chosen->fourcc == V4L2_PIX_FMT_YUYV  ? "luma plane copied, no decode"
                        : chosen->fourcc == V4L2_PIX_FMT_MJPEG ? "decoded"
                                                               : "converted to grayscale",
                        passed_over.empty() ? "" : "; " + passed_over, rate_note);
    } else {
        out.reason = fmt::format("{} as configured{}", chosen->name, rate_note);
    }
    return 0;
}

int V4l2Device::allocateBuffers(int count)
{
    releaseBuffers();
    v4l2_requestbuffers request{};
    request.count = static_cast<uint32_t>(std::max(count, 2));
    request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    request.memory = V4L2_MEMORY_MMAP;
    if (const int rc = xioctl(VIDIOC_REQBUFS, &request); rc < 0)
        return fail("VIDIOC_REQBUFS", -rc);
    if (request.count < 2) {
        error_ = fmt::format("{}: the driver gave {} buffer(s), streaming needs at least 2", path_,
                             request.count);
        return -ENOMEM;
    }
    buffers_.reserve(request.count);
    for (uint32_t i = 0; i < request.count; ++i) {
        v4l2_buffer buffer{};
        buffer.index = i;
        buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        buffer.memory = V4L2_MEMORY_MMAP;
        if (const int rc = xioctl(VIDIOC_QUERYBUF, &buffer); rc < 0) {
            const int result = fail("VIDIOC_QUERYBUF", -rc);
            releaseBuffers();
            return result;
        }
        void* data = v4l2_mmap(nullptr, buffer.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_,
                               buffer.m.offset);
        if (data == MAP_FAILED) {
            const int result = fail("mmap of a capture buffer", errno);
            releaseBuffers();
            return result;
        }
        buffers_.push_back(MappedBuffer{static_cast<uint8_t*>(data), buffer.length});
    }
    return 0;
}

void V4l2Device::releaseBuffers() noexcept
{
    if (buffers_.empty())
        return;
    for (const MappedBuffer& buffer : buffers_)
        v4l2_munmap(buffer.data, buffer.length);
    buffers_.clear();
    v4l2_requestbuffers request{};
    request.count = 0;
    request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    request.memory = V4L2_MEMORY_MMAP;
    xioctl(VIDIOC_REQBUFS, &request); // a vanished device refuses; nothing left to free then
}

int V4l2Device::queueBuffer(uint32_t index)
{
    v4l2_buffer buffer{};
    buffer.index = index;
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    if (const int rc = xioctl(VIDIOC_QBUF, &buffer); rc < 0)
        return fail("VIDIOC_QBUF", -rc);
    return 0;
}

int V4l2Device::dequeueBuffer(DequeuedBuffer& out)
{
    v4l2_buffer buffer{};
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    if (const int rc = xioctl(VIDIOC_DQBUF, &buffer); rc < 0)
        return rc == -EAGAIN ? rc : fail("VIDIOC_DQBUF", -rc);
    if (buffer.index >= buffers_.size()) {
        error_ = fmt::format("{}: VIDIOC_DQBUF returned buffer {} of {}", path_, buffer.index,
                             buffers_.size());
        return -EIO;
    }
    out.index = buffer.index;
    out.bytes_used = buffer.bytesused;
    out.flags = buffer.flags;
    out.sequence = buffer.sequence;
    out.timestamp_ns = static_cast<int64_t>(buffer.timestamp.tv_sec) * 1'000'000'000 +
                       static_cast<int64_t>(buffer.timestamp.tv_usec) * 1000;
    return 0;
}

int V4l2Device::streamOn()
{
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (const int rc = xioctl(VIDIOC_STREAMON, &type); rc < 0)
        return fail("VIDIOC_STREAMON", -rc);
    streaming_ = true;
    return 0;
}

int V4l2Device::streamOff() noexcept
{
    if (!streaming_ || fd_ < 0)
        return 0;
    streaming_ = false;
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    return xioctl(VIDIOC_STREAMOFF, &type);
}

} // namespace stereod
