#include "capture/format_choice.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <linux/videodev2.h>

namespace stereod {

namespace {

// The formats we can turn into grayscale, in the order `auto` prefers them.
constexpr uint32_t kAutoOrder[] = {V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG,
                                   V4L2_PIX_FMT_RGB24, V4L2_PIX_FMT_BGR24};

constexpr double kRateTolerance = 0.01; // a rate matches within 1 %

uint32_t choiceFourcc(PixelFormatChoice choice) noexcept
{
    switch (choice) {
    case PixelFormatChoice::Grey:
        return V4L2_PIX_FMT_GREY;
    case PixelFormatChoice::Yuyv:
        return V4L2_PIX_FMT_YUYV;
    case PixelFormatChoice::Mjpeg:
        return V4L2_PIX_FMT_MJPEG;
    case PixelFormatChoice::Rgb24:
        return V4L2_PIX_FMT_RGB24;
    case PixelFormatChoice::Bgr24:
        return V4L2_PIX_FMT_BGR24;
    case PixelFormatChoice::Auto:
        break;
    }
    return 0;
}

} // namespace

uint32_t bytesPerPixel(uint32_t fourcc) noexcept
{
    switch (fourcc) {
    case V4L2_PIX_FMT_GREY:
        return 1;
    case V4L2_PIX_FMT_YUYV:
        return 2;
    case V4L2_PIX_FMT_RGB24:
    case V4L2_PIX_FMT_BGR24:
        return 3;
    default:
        return 0;
    }
}

bool carriesColour(uint32_t fourcc) noexcept
{
    return fourcc == V4L2_PIX_FMT_YUYV || fourcc == V4L2_PIX_FMT_MJPEG ||
           fourcc == V4L2_PIX_FMT_RGB24 || fourcc == V4L2_PIX_FMT_BGR24;
}

bool sameRate(double a, double b) noexcept
{
    return std::abs(a - b) <= kRateTolerance * std::max(a, b);
}

std::string formatRate(double fps)
{
    return std::abs(fps - std::round(fps)) < 0.005 ? fmt::format("{:.0f}", fps)
                                                   : fmt::format("{:.2f}", fps);
}

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

FormatChoice chooseFormat(const std::vector<FormatDescription>& offered,
                          const CameraSettings& settings)
{
    const bool is_auto = settings.format == PixelFormatChoice::Auto;
    std::vector<uint32_t> candidates;
    if (is_auto)
        candidates.assign(std::begin(kAutoOrder), std::end(kAutoOrder));
    else
        candidates.push_back(choiceFourcc(settings.format));

    FormatChoice choice;
    std::string& passed_over = choice.passed_over;
    for (uint32_t fourcc : candidates) {
        const auto it =
            std::find_if(offered.begin(), offered.end(),
                         [fourcc](const FormatDescription& f) { return f.fourcc == fourcc; });
        if (it == offered.end()) {
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
            choice.format = &*it;
            return choice;
        }
        passed_over +=
            fmt::format("{}{} not at {}x{} @ {} fps", passed_over.empty() ? "" : "; ", it->name,
                        settings.width, settings.height, formatRate(settings.fps));
    }

    std::string listing;
    for (const FormatDescription& f : offered) {
        const bool usable = std::find(std::begin(kAutoOrder), std::end(kAutoOrder), f.fourcc) !=
                            std::end(kAutoOrder);
        listing += fmt::format("{}{}{}", listing.empty() ? "" : "; ", describeFormat(f),
                               usable ? "" : " (not usable)");
    }
    choice.refusal = fmt::format(
        "cannot deliver {} {}x{} @ {} fps; it offers: {}",
        is_auto ? "GREY, YUYV, MJPG, RGB3 or BGR3" : fourccName(candidates[0]), settings.width,
        settings.height, formatRate(settings.fps), listing.empty() ? "no formats" : listing);
    return choice;
}

} // namespace stereod
