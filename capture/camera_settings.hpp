#pragma once
// What a rig asks of each V4L2 camera (format, size, rate, controls, buffers and timing)
// and what a camera settled on: plain settings, shared by the device, the camera, the
// configuration and status, with no device code.

#include <cstdint>
#include <optional>
#include <string>

#include "base/name_table.hpp"

namespace stereod {

// Pixel format asked of the device. `Auto` takes the first the device offers at the
// asked size and rate, in the order GREY > YUYV > MJPEG > RGB24 > BGR24: GREY needs no
// work and no copy, YUYV only a luma copy, MJPEG a decode (and JPEG artefacts hurt
// matching), packed RGB/BGR a grey conversion of three times the bytes.
enum class PixelFormatChoice { Auto, Grey, Yuyv, Mjpeg, Rgb24, Bgr24 };

// The names of source.cameras.format, one table for naming and parsing them.
inline constexpr NameTable<PixelFormatChoice, 6> kPixelFormatChoices{{{
    {PixelFormatChoice::Auto, "auto"},
    {PixelFormatChoice::Grey, "grey"},
    {PixelFormatChoice::Yuyv, "yuyv"},
    {PixelFormatChoice::Mjpeg, "mjpeg"},
    {PixelFormatChoice::Rgb24, "rgb24"},
    {PixelFormatChoice::Bgr24, "bgr24"},
}}};
static_assert(kPixelFormatChoices.wellFormed());

const char* toString(PixelFormatChoice format) noexcept;
// One of kPixelFormatChoices' names, in any case ("GREY" as V4L2 writes it); nothing for
// anything else.
std::optional<PixelFormatChoice> parsePixelFormatChoice(const std::string& text) noexcept;

// V4L2_CID_POWER_LINE_FREQUENCY menu (anti-flicker under mains lighting).
enum class PowerLineFrequency { Disabled = 0, Hz50 = 1, Hz60 = 2, Auto = 3 };

// The names of source.cameras.controls.power_line_frequency.
inline constexpr NameTable<PowerLineFrequency, 4> kPowerLineFrequencies{{{
    {PowerLineFrequency::Disabled, "disabled"},
    {PowerLineFrequency::Hz50, "50hz"},
    {PowerLineFrequency::Hz60, "60hz"},
    {PowerLineFrequency::Auto, "auto"},
}}};
static_assert(kPowerLineFrequencies.wellFormed());

// Controls applied alike to every camera of a rig. An unset field leaves the device's
// value alone. Two cameras with different exposure or gain ruin matching, so what each
// camera actually accepted is read back and reported (V4l2CameraStatus::controls).
struct CameraControls {
    std::optional<bool> auto_exposure;      // V4L2_CID_EXPOSURE_AUTO (true: auto, false: manual)
    std::optional<int32_t> exposure_us;     // V4L2_CID_EXPOSURE_ABSOLUTE (device unit: 100 us)
    std::optional<int32_t> gain;            // V4L2_CID_GAIN, device units
    std::optional<bool> auto_white_balance; // V4L2_CID_AUTO_WHITE_BALANCE
    std::optional<int32_t> white_balance_k; // V4L2_CID_WHITE_BALANCE_TEMPERATURE, kelvin
    std::optional<PowerLineFrequency> power_line; // V4L2_CID_POWER_LINE_FREQUENCY
};

struct CameraSettings {
    std::string device; // /dev/videoN or a /dev/v4l/by-id/... link;
                        // reopened by this same path
    PixelFormatChoice format = PixelFormatChoice::Auto;
    int width = 640; // px; the device must offer exactly this size
    int height = 480;
    double fps = 30.0; // asked frame rate (S_PARM); the driver's
                       // actual rate is reported
    CameraControls controls;
    // Manual exposure with auto exposure off: controls.exposure_us when set, otherwise
    // the exposure the device has at open time (frozen there).
    bool lock_exposure = false;
    // V4L2 mmap buffers asked for (REQBUFS), >= 2. GREY frames are the buffers
    // themselves: frames waiting in the consumer's ring or held by it count against these,
    // so keep ring capacity + frames held below this (else: pool exhausted, frames lost).
    int buffer_count = 6;
    // No frame for this long (while buffers are queued) means Stalled; 0: five frame
    // periods at the negotiated rate, at least 200 ms.
    int stall_timeout_ms = 0;
    int reopen_min_ms = 100;  // first reopen delay after a failure
    int reopen_max_ms = 2000; // the delay doubles up to this
    // Keep the camera's colour beside the grey image (Frame::colour) when its format has
    // colour (YUYV, MJPEG, RGB24, BGR24); a GREY camera has none to keep, at no cost.
    bool keep_colour = false;
};

// What the device settled on after negotiation.
struct NegotiatedFormat {
    uint32_t fourcc = 0;     // V4L2_PIX_FMT_GREY / _YUYV / _MJPEG / _RGB24 / _BGR24
    std::string format_name; // "GREY", "YUYV", "MJPG", "RGB3", "BGR3"
    int width = 0;
    int height = 0;
    uint32_t bytes_per_line = 0; // 0 for compressed formats
    uint32_t size_image = 0;     // bytes of one buffer as the driver sized it
    double fps = 0.0;            // the rate the driver set (from S_PARM)
    std::string reason;          // why this format (auto choice, or as asked)
    bool colour = false; // frames carry the camera's colour (keep_colour and a colour format)
    // YUYV uses the whole 0..255 range (V4L2_QUANTIZATION_FULL_RANGE, or the JPEG
    // colorspace); false: BT.601 limited range (16..235), V4L2's default for YUV.
    bool full_range = false;
};

// One control after apply and read-back.
struct ControlReading {
    std::string name;            // "exposure_us", "gain", ...
    uint32_t id = 0;             // V4L2_CID_*
    bool present = false;        // the device has it
    bool requested = false;      // the settings asked for a value
    int64_t requested_value = 0; // in the unit of `name`
    int64_t actual_value = 0;    // read back from the device, same unit
    std::string error;           // why the request was not met; empty if met
};

} // namespace stereod
