#include "capture/camera_settings.hpp"

#include <strings.h>

namespace stereod {

const char* toString(PixelFormatChoice format) noexcept
{
    switch (format) {
    case PixelFormatChoice::Auto:
        return "auto";
    case PixelFormatChoice::Grey:
        return "grey";
    case PixelFormatChoice::Yuyv:
        return "yuyv";
    case PixelFormatChoice::Mjpeg:
        return "mjpeg";
    case PixelFormatChoice::Rgb24:
        return "rgb24";
    case PixelFormatChoice::Bgr24:
        return "bgr24";
    }
    return "unknown";
}

std::optional<PixelFormatChoice> parsePixelFormatChoice(const std::string& text) noexcept
{
    for (PixelFormatChoice choice :
         {PixelFormatChoice::Auto, PixelFormatChoice::Grey, PixelFormatChoice::Yuyv,
          PixelFormatChoice::Mjpeg, PixelFormatChoice::Rgb24, PixelFormatChoice::Bgr24}) {
        if (strcasecmp(text.c_str(), toString(choice)) == 0)
            return choice;
    }
    return std::nullopt;
}

} // namespace stereod
