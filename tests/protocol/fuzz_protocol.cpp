// libFuzzer entry point for the protocol parser: any bytes must give a request or a
// protocol error, never a crash, a hang or an exception; and every reply built from the
// result (an error that quotes the input, a reading with a message made of the input)
// must be one line of valid JSON.
//
// Built with clang by tests/fuzz/CMakeLists.txt and run by scripts/fuzz.sh [SECONDS]
// from the seeds in tests/fuzz/corpus/protocol/ with tests/protocol/fuzz_protocol.dict.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "protocol/events.hpp"
#include "protocol/reply.hpp"
#include "protocol/request.hpp"

namespace {

void checkLine(const std::string& line)
{
    if (line.empty() || line.back() != '\n' || line.find('\n') != line.size() - 1)
        __builtin_trap();
    // Strict: throws on anything that is not valid JSON (invalid UTF-8 included).
    const stereod::Json parsed = stereod::Json::parse(line);
    if (!parsed.is_object())
        __builtin_trap();
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    const std::string_view input(reinterpret_cast<const char*>(data), size);
    const stereod::ParseResult result = stereod::parseRequest(input);
    std::string line;
    if (const auto* error = std::get_if<stereod::ProtocolError>(&result)) {
        if (error->message.empty())
            __builtin_trap();
        stereod::appendJsonLine(line, stereod::errorReply(error->code, error->message, error->id));
    } else {
        const auto& request = std::get<stereod::Request>(result);
        stereod::appendJsonLine(line, stereod::helloReply(request.id));
    }
    checkLine(line);

    // The same bytes as a reason message (exception texts end up there).
    stereod::ReadingReport report;
    report.reading.reason = stereod::NoReadingReason::BadFrame;
    report.detail = input;
    line.clear();
    stereod::appendReadingEvent(line, report, 0, 1);
    checkLine(line);
    return 0;
}
