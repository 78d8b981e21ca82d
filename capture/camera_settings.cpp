#include "capture/camera_settings.hpp"

#include <algorithm>
#include <cctype>

namespace stereod {

const char* toString(PixelFormatChoice format) noexcept
{
    return kPixelFormatChoices.name(format, "unknown");
}

std::optional<PixelFormatChoice> parsePixelFormatChoice(const std::string& text) noexcept
{
    char lower[8] = {};
    if (text.size() >= sizeof lower)
        return std::nullopt;
    std::transform(text.begin(), text.end(), lower,
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return kPixelFormatChoices.parse(lower);
}

} // namespace stereod
