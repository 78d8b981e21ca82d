// libFuzzer target: a bag's Image message (any bytes a file may hold) decoded for the
// pipeline must give an 8-bit grayscale image of the size it declares, or a reason, never
// crash, read out of bounds or allocate what a field merely states.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include <opencv2/core/mat.hpp>

#include "replay/image_message.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    const std::string_view message(reinterpret_cast<const char*>(data), size);
    cv::Mat out;
    std::string reason;
    if (stereod::decodeImageMessage(message, {}, out, reason)) {
        if (out.empty() || out.type() != CV_8UC1)
            __builtin_trap(); // a decoded image is always 8-bit grayscale
    } else if (reason.empty()) {
        __builtin_trap(); // a refusal always says why
    }
    return 0;
}
