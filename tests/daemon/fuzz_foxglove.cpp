// libFuzzer target: the live view's parser of client messages (any text a WebSocket
// client may send) must answer every input with a request or a reason, never crash.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "daemon/live_view/foxglove_protocol.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    const auto request = stereod::live_view::parseClientMessage(text);
    if (request.kind == stereod::live_view::ClientRequest::Kind::Invalid && request.problem.empty())
        __builtin_trap(); // a refusal always says why
    std::string frame;
    stereod::live_view::appendMessageData(1, 2, text, frame);
    if (frame.size() != size + 13)
        __builtin_trap();
    return 0;
}
