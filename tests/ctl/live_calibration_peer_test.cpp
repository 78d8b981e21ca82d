// `stereoctl calibrate --live` against a scripted peer that answers like a service and then
// sends raw events that are wrong: each ends the run with one message naming the frame and
// the image (or payload) at fault and the unreachable exit code, never a crash or a hang. A
// payload this stereoctl does not know is read past and the stream stays in step.

#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/support/process.hpp"
#include "tests/support/scripted_peer.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using Json = nlohmann::ordered_json;
using test::ProcessResult;
using test::readRequestLine;
using test::runProcess;
using test::stereoctlPath;
using test::writeAll;

constexpr int kWidth = 16;
constexpr int kHeight = 12;

Json grey(const char* name, int bytes)
{
    return {{"name", name},
            {"format", "u8_gray"},
            {"width", kWidth},
            {"height", kHeight},
            {"bytes", bytes}};
}

// A raw event line with its payload headers, followed by `body` as its payload bytes.
std::string rawEvent(uint64_t frame, const Json& payloads, const std::string& body)
{
    Json event = {{"event", "raw"}, {"frame", frame}, {"skipped", 0}};
    if (!payloads.is_null())
        event["payloads"] = payloads;
    return event.dump() + "\n" + body;
}

std::string pixels(int bytes)
{
    return std::string(static_cast<std::size_t>(bytes), '\x80');
}

// Runs the live calibration against a peer that answers hello and subscribe, then sends
// `events` and hangs up (`hang_up`) or waits for the client to.
ProcessResult calibrateAgainst(const std::string& events, bool hang_up)
{
    test::TempDir dir;
    const std::string socket = dir.file("s.sock");
    Json hello_request;
    Json subscribe_request;
    ProcessResult run;
    {
        test::ScriptedPeer peer(socket, [&](int fd) {
            hello_request = Json::parse(readRequestLine(fd));
            writeAll(fd, R"({"ok": true, "streams": ["reading", "raw"]})"
                         "\n");
            subscribe_request = Json::parse(readRequestLine(fd));
            writeAll(fd, "{\"ok\": true}\n");
            writeAll(fd, events);
            if (!hang_up)
                readRequestLine(fd); // until the client closes
        });
        run = runProcess({stereoctlPath(), "calibrate", "--live", "--board", "9x6", "--square-m",
                          "0.025", "--count", "8", "--out", dir.file("rig.yaml"), "--socket",
                          socket});
    }
    EXPECT_EQ(hello_request.value("cmd", ""), "hello");
    EXPECT_EQ(subscribe_request.value("stream", ""), "raw");
    return run;
}

TEST(StereoctlCalibrateLive, AWrongRawEventEndsTheRunWithAMessageNamingIt)
{
    constexpr int kBytes = kWidth * kHeight;
    struct Case {
        const char* what;
        std::string events;
        const char* message;
        bool hang_up = false;
    };
    const std::vector<Case> cases = {
        {"no right image", rawEvent(7, Json::array({grey("raw_left", kBytes)}), pixels(kBytes)),
         "(frame 7) lacks the raw_right u8_gray payload"},
        {"no left image", rawEvent(7, Json::array({grey("raw_right", kBytes)}), pixels(kBytes)),
         "(frame 7) lacks the raw_left u8_gray payload"},
        {"no image", rawEvent(7, Json::array(), ""),
         "(frame 7) lacks the raw_left and raw_right u8_gray payloads"},
        {"no payloads list", rawEvent(7, Json(), ""), "has no payloads list"},
        {"a size that does not add up",
         rawEvent(7, Json::array({grey("raw_left", kBytes + 1), grey("raw_right", kBytes)}),
                  pixels(2 * kBytes + 1)),
         "raw_left payload of 16x12 u8_gray in 193 bytes, which does not add up"},
        {"an image cut short",
         rawEvent(7, Json::array({grey("raw_left", kBytes), grey("raw_right", kBytes)}),
                  pixels(kBytes + 10)),
         "closed the connection after 10 of 192 payload bytes", true},
        // Read past, in step: the next event's fault is the one reported.
        {"an unknown payload, then a frame without its right image",
         rawEvent(7,
                  Json::array({grey("raw_left", kBytes),
                               grey("raw_right", kBytes),
                               {{"name", "from_the_future"}, {"bytes", 5}}}),
                  pixels(2 * kBytes + 5)) +
             rawEvent(8, Json::array({grey("raw_left", kBytes)}), pixels(kBytes)),
         "(frame 8) lacks the raw_right u8_gray payload"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        const ProcessResult run = calibrateAgainst(c.events, c.hang_up);
        EXPECT_EQ(run.exit_code, 3) << run.err;
        EXPECT_NE(run.err.find(c.message), std::string::npos) << run.err;
        EXPECT_EQ(run.err.find("stereoctl: "), run.err.rfind("stereoctl: ")) << run.err;
    }
}

} // namespace
} // namespace stereod
