#pragma once
// What a V4L2 device offers (formats, sizes, rates) and the choice among it, as pure
// functions of the device's answers, so that the automatic choice is tested without a
// device.

#include <cstdint>
#include <string>
#include <vector>

#include "capture/camera_settings.hpp"

namespace stereod {

// One frame size a format offers, with the frame rates offered at that size.
struct FrameSizeDescription {
    int width = 0; // px; a discrete size, or the smallest of a range
    int height = 0;
    int max_width = 0; // px; a range (stepwise/continuous) when > 0
    int max_height = 0;
    int step_width = 0;
    int step_height = 0;
    std::vector<double> fps; // discrete rates, fastest first
    double min_fps = 0.0;    // a range of rates when max_fps > 0
    double max_fps = 0.0;

    bool isRange() const noexcept { return max_width > 0; }
    bool contains(int w, int h) const noexcept;
    bool offersRate(double rate) const noexcept; // within 1 %
};

struct FormatDescription {
    uint32_t fourcc = 0;
    std::string name;        // the fourcc as text: "GREY", "YUYV", "MJPG"
    std::string description; // the driver's text
    bool compressed = false;
    std::vector<FrameSizeDescription> sizes;
};

// "GREY" for V4L2_PIX_FMT_GREY, etc.
std::string fourccName(uint32_t fourcc);
// "YUYV 640x480 @ 30/15 fps, 1280x720 @ 10 fps": what a format offers, for messages.
std::string describeFormat(const FormatDescription& format);

// Bytes per pixel of an uncompressed format's rows: GREY 1, YUYV 2, RGB3/BGR3 3; 0 for
// MJPEG (compressed) and formats we do not take.
uint32_t bytesPerPixel(uint32_t fourcc) noexcept;
// Whether a format carries colour: YUYV, MJPEG (colour JPEG), RGB3, BGR3.
bool carriesColour(uint32_t fourcc) noexcept;

// 30 -> "30", 29.97 -> "29.97".
std::string formatRate(double fps);
// Equal within 1 %.
bool sameRate(double a, double b) noexcept;

// The format to ask for, among those a device offers: the configured one, or for `auto`
// the first of GREY > YUYV > MJPEG > RGB3 > BGR3 offered at the asked size and rate (GREY
// needs no work, YUYV a luma copy, MJPEG a decode, packed RGB a conversion of 3 bytes a
// pixel).
struct FormatChoice {
    const FormatDescription* format = nullptr; // into the offered list; nullptr: none fits
    std::string passed_over; // for `auto`: the better formats and why they were not taken
    std::string refusal;     // when none fits: what was asked and what the device offers
};
FormatChoice chooseFormat(const std::vector<FormatDescription>& offered,
                          const CameraSettings& settings);

} // namespace stereod
