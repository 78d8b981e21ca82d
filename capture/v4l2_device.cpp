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

namespace stereod {

namespace {

constexpr double kRateTolerance = 0.01; // a rate matches within 1 %

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

bool sameRate(double a, double b) noexcept
{
    return std::abs(a - b) <= kRateTolerance * std::max(a, b);
}

std::string fixedText(const uint8_t* text, std::size_t size)
{
    const auto* chars = reinterpret_cast<const char*>(text);
    return std::string(chars, strnlen(chars, size));
}

std::string formatRate(double fps)
{
    return std::abs(fps - std::round(fps)) < 0.005 ? fmt::format("{:.0f}", fps)
                                                   : fmt::format("{:.2f}", fps);
}

// The formats we can turn into grayscale, in the order `auto` prefers them.
constexpr uint32_t kAutoOrder[] = {V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG};

uint32_t choiceFourcc(PixelFormatChoice choice) noexcept
{
    switch (choice) {
    case PixelFormatChoice::Grey:
        return V4L2_PIX_FMT_GREY;
    case PixelFormatChoice::Yuyv:
        return V4L2_PIX_FMT_YUYV;
    case PixelFormatChoice::Mjpeg:
        return V4L2_PIX_FMT_MJPEG;
    case PixelFormatChoice::Auto:
        break;
    }
    return 0;
}

} // namespace

bool FrameSizeDescription::contains(int w, int h) const noexcept
{
    if (!isRange())
        return w == width && h == height;
    const int sw = std::max(step_width, 1);
    const int sh = std::max(step_height, 1);
    return w >= width && w <= max_width && h >= height && h <= max_height &&
           (w - width) % sw == 0 && (h - height) % sh == 0;
}

bool FrameSizeDescription::offersRate(double rate) const noexcept
{
    if (max_fps > 0.0 && rate >= min_fps * (1.0 - kRateTolerance) &&
        rate <= max_fps * (1.0 + kRateTolerance))
        return true;
    return std::any_of(fps.begin(), fps.end(), [rate](double f) { return sameRate(f, rate); });
}

std::string fourccName(uint32_t fourcc)
{
    std::string name;
    for (int i = 0; i < 4; ++i) {
        const char c = static_cast<char>((fourcc >> (8 * i)) & 0xff);
        if (c != ' ' && c != '\0')
            name.push_back(c);
    }
    return name;
}

std::string describeFormat(const FormatDescription& format)
{
    std::string text = format.name;
    const char* separator = " ";
    for (const FrameSizeDescription& size : format.sizes) {
        text += separator;
        separator = ", ";
        if (size.isRange())
            text += fmt::format("{}x{}..{}x{} step {}x{}", size.width, size.height, size.max_width,
                                size.max_height, size.step_width, size.step_height);
        else
            text += fmt::format("{}x{}", size.width, size.height);
        if (!size.fps.empty()) {
            text += " @ ";
            for (std::size_t i = 0; i < size.fps.size(); ++i)
                text += (i == 0 ? "" : "/") + formatRate(size.fps[i]);
            text += " fps";
        } else if (size.max_fps > 0.0) {
            text +=
                fmt::format(" @ {}..{} fps", formatRate(size.min_fps), formatRate(size.max_fps));
        }
    }
    if (format.sizes.empty())
        text += " (no sizes listed)";
    return text;
}

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
    error_ = fmt::format("{} on {}: {}", what, path_, std::strerror(error_number));
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
    const int fd = ::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0)
        return fail("open", errno);
    // See the header: no libv4l2 format emulation, we want the camera's own formats.
    if (v4l2_fd_open(fd, V4L2_DISABLE_CONVERSION) < 0) {
        const int error_number = errno;
        ::close(fd);
        return fail("v4l2_fd_open", error_number);
    }
    fd_ = fd;

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
    std::vector<uint32_t> candidates;
    if (is_auto)
        candidates.assign(std::begin(kAutoOrder), std::end(kAutoOrder));
    else
        candidates.push_back(choiceFourcc(settings.format));

    const FormatDescription* chosen = nullptr;
    std::string passed_over; // for `auto`: the better formats and why they were not taken
    for (uint32_t fourcc : candidates) {
        const auto it =
            std::find_if(formats.begin(), formats.end(),
                         [fourcc](const FormatDescription& f) { return f.fourcc == fourcc; });
        if (it == formats.end()) {
            passed_over += fmt::format("{}{} not offered", passed_over.empty() ? "" : "; ",
                                       fourccName(fourcc));
            continue;
        }
        // A driver that lists no sizes (no ENUM_FRAMESIZES) is trusted to S_FMT below.
        const bool size_ok =
            it->sizes.empty() ||
            std::any_of(it->sizes.begin(), it->sizes.end(), [&](const FrameSizeDescription& s) {
                return s.contains(settings.width, settings.height);
            });
        bool rate_ok = true;
        if (size_ok && !it->sizes.empty()) {
            rate_ok = false;
            for (const FrameSizeDescription& s : it->sizes) {
                if (!s.contains(settings.width, settings.height))
                    continue;
                // No listed rates: the driver does not enumerate them; S_PARM decides.
                if ((s.fps.empty() && s.max_fps <= 0.0) || s.offersRate(settings.fps))
                    rate_ok = true;
            }
        }
        if (size_ok && rate_ok) {
            chosen = &*it;
            break;
        }
        passed_over +=
            fmt::format("{}{} not at {}x{} @ {} fps", passed_over.empty() ? "" : "; ", it->name,
                        settings.width, settings.height, formatRate(settings.fps));
    }

    if (chosen == nullptr) {
        std::string offered;
        for (const FormatDescription& f : formats) {
            const bool usable = std::find(std::begin(kAutoOrder), std::end(kAutoOrder), f.fourcc) !=
                                std::end(kAutoOrder);
            offered += fmt::format("{}{}{}", offered.empty() ? "" : "; ", describeFormat(f),
                                   usable ? "" : " (not usable)");
        }
        error_ = fmt::format(
            "{} ({}) cannot deliver {} {}x{} @ {} fps; it offers: {}", path_, identity_.card,
            is_auto ? "GREY, YUYV or MJPG" : fourccName(candidates[0]), settings.width,
            settings.height, formatRate(settings.fps), offered.empty() ? "no formats" : offered);
        return -EINVAL;
    }

    v4l2_format format{};
    format.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    format.fmt.pix.pixelformat = chosen->fourcc;
    format.fmt.pix.width = static_cast<uint32_t>(settings.width);
    format.fmt.pix.height = static_cast<uint32_t>(settings.height);
    format.fmt.pix.field = V4L2_FIELD_NONE;
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
    const uint32_t min_line =
        chosen->fourcc == V4L2_PIX_FMT_YUYV ? 2 * format.fmt.pix.width : format.fmt.pix.width;
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

    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    parm.parm.capture.timeperframe = fpsToInterval(settings.fps);
    std::string rate_note;
    if (const int rc = xioctl(VIDIOC_S_PARM, &parm); rc < 0) {
        rate_note = fmt::format(", frame rate not settable ({})", std::strerror(-rc));
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
            fmt::format("auto chose {} at {}x{} @ {} fps (preference GREY > YUYV > MJPG: "
                        "{}){}{}",
                        chosen->name, settings.width, settings.height, formatRate(settings.fps),
                        chosen->fourcc == V4L2_PIX_FMT_GREY   ? "no conversion, no copy"
                        : chosen->fourcc == V4L2_PIX_FMT_YUYV ? "luma plane copied, no decode"
                                                              : "decoded to grayscale",
                        passed_over.empty() ? "" : "; " + passed_over, rate_note);
    } else {
        out.reason = fmt::format("{} as configured{}", chosen->name, rate_note);
    }
    return 0;
}

int V4l2Device::queryControl(uint32_t id, v4l2_queryctrl& query)
{
    query = v4l2_queryctrl{};
    query.id = id;
    if (const int rc = xioctl(VIDIOC_QUERYCTRL, &query); rc < 0)
        return rc;
    if ((query.flags & V4L2_CTRL_FLAG_DISABLED) != 0)
        return -EINVAL;
    return 0;
}

ControlReading V4l2Device::readControl(const char* name, uint32_t id, int64_t unit)
{
    ControlReading reading;
    reading.name = name;
    reading.id = id;
    v4l2_queryctrl query{};
    if (queryControl(id, query) < 0)
        return reading;
    reading.present = true;
    v4l2_control control{};
    control.id = id;
    if (const int rc = xioctl(VIDIOC_G_CTRL, &control); rc < 0)
        reading.error = fmt::format("VIDIOC_G_CTRL: {}", std::strerror(-rc));
    else
        reading.actual_value = static_cast<int64_t>(control.value) * unit;
    return reading;
}

ControlReading V4l2Device::setControl(const char* name, uint32_t id, int64_t value, int64_t unit)
{
    ControlReading reading;
    reading.name = name;
    reading.id = id;
    reading.requested = true;
    reading.requested_value = value;
    v4l2_queryctrl query{};
    if (queryControl(id, query) < 0) {
        reading.error = "not offered by the device";
        return reading;
    }
    reading.present = true;

    // Values in the unit of `name` (exposure in us) become device units (100 us).
    int64_t raw = (value + unit / 2) / unit;
    if (query.type == V4L2_CTRL_TYPE_INTEGER || query.type == V4L2_CTRL_TYPE_BOOLEAN) {
        const int64_t step = std::max<int64_t>(query.step, 1);
        const int64_t clamped =
            query.minimum +
            (std::clamp<int64_t>(raw, query.minimum, query.maximum) - query.minimum) / step * step;
        if (clamped != raw)
            reading.error = fmt::format("asked {}, device range {}..{} step {}: set {}", value,
                                        query.minimum * unit, query.maximum * unit, step * unit,
                                        clamped * unit);
        raw = clamped;
    }
    v4l2_control control{};
    control.id = id;
    control.value = static_cast<int32_t>(raw);
    if (const int rc = xioctl(VIDIOC_S_CTRL, &control); rc < 0)
        reading.error = fmt::format("VIDIOC_S_CTRL refused {}: {}", value, std::strerror(-rc));

    const ControlReading read_back = readControl(name, id, unit);
    reading.actual_value = read_back.actual_value;
    if (!read_back.error.empty())
        reading.error = read_back.error;
    else if (reading.error.empty() && read_back.actual_value != raw * unit)
        reading.error = fmt::format("device kept {}", read_back.actual_value);
    return reading;
}

std::vector<ControlReading> V4l2Device::applyControls(const CameraControls& controls,
                                                      bool lock_exposure)
{
    std::vector<ControlReading> readings;
    // Auto exposure first: the absolute exposure is inactive (or refused) while it is on.
    if (lock_exposure || controls.auto_exposure.has_value()) {
        const bool want_auto = !lock_exposure && *controls.auto_exposure;
        ControlReading reading =
            setControl("auto_exposure", V4L2_CID_EXPOSURE_AUTO,
                       want_auto ? V4L2_EXPOSURE_AUTO : V4L2_EXPOSURE_MANUAL, 1);
        // Many UVC cameras offer only manual and aperture priority (their "auto").
        if (want_auto && reading.present && !reading.error.empty()) {
            ControlReading aperture = setControl("auto_exposure", V4L2_CID_EXPOSURE_AUTO,
                                                 V4L2_EXPOSURE_APERTURE_PRIORITY, 1);
            if (aperture.error.empty())
                reading = aperture;
        }
        readings.push_back(std::move(reading));
    }
    if (controls.exposure_us.has_value()) {
        readings.push_back(
            setControl("exposure_us", V4L2_CID_EXPOSURE_ABSOLUTE, *controls.exposure_us, 100));
    } else if (lock_exposure) {
        // Freeze the exposure the device has now.
        const ControlReading current = readControl("exposure_us", V4L2_CID_EXPOSURE_ABSOLUTE, 100);
        if (current.present && current.error.empty())
            readings.push_back(
                setControl("exposure_us", V4L2_CID_EXPOSURE_ABSOLUTE, current.actual_value, 100));
        else
            readings.push_back(current);
    }
    if (controls.gain.has_value())
        readings.push_back(setControl("gain", V4L2_CID_GAIN, *controls.gain, 1));
    if (controls.auto_white_balance.has_value() || controls.white_balance_k.has_value()) {
        const bool want_auto =
            controls.white_balance_k.has_value() ? false : *controls.auto_white_balance;
        readings.push_back(
            setControl("auto_white_balance", V4L2_CID_AUTO_WHITE_BALANCE, want_auto ? 1 : 0, 1));
    }
    if (controls.white_balance_k.has_value())
        readings.push_back(setControl("white_balance_k", V4L2_CID_WHITE_BALANCE_TEMPERATURE,
                                      *controls.white_balance_k, 1));
    if (controls.power_line.has_value())
        readings.push_back(setControl("power_line_frequency", V4L2_CID_POWER_LINE_FREQUENCY,
                                      static_cast<int64_t>(*controls.power_line), 1));

    // Then everything else the project knows, as the device has it.
    for (ControlReading& reading : readControls()) {
        const bool listed =
            std::any_of(readings.begin(), readings.end(),
                        [&](const ControlReading& r) { return r.id == reading.id; });
        if (!listed)
            readings.push_back(std::move(reading));
    }
    return readings;
}

std::vector<ControlReading> V4l2Device::readControls()
{
    struct Known {
        const char* name;
        uint32_t id;
        int64_t unit;
    };
    static constexpr Known kKnown[] = {
        {"auto_exposure", V4L2_CID_EXPOSURE_AUTO, 1},
        {"exposure_us", V4L2_CID_EXPOSURE_ABSOLUTE, 100},
        {"gain", V4L2_CID_GAIN, 1},
        {"auto_white_balance", V4L2_CID_AUTO_WHITE_BALANCE, 1},
        {"white_balance_k", V4L2_CID_WHITE_BALANCE_TEMPERATURE, 1},
        {"power_line_frequency", V4L2_CID_POWER_LINE_FREQUENCY, 1},
    };
    std::vector<ControlReading> readings;
    for (const Known& known : kKnown) {
        ControlReading reading = readControl(known.name, known.id, known.unit);
        if (reading.present)
            readings.push_back(std::move(reading));
    }
    return readings;
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
