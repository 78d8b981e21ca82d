// The live view's threads in one process, against a plain WebSocket client: the channels a
// client subscribes to arrive under its subscription ids and at their own rates, and a
// client that never reads loses frames, is closed once and counted, while the others go
// on. Labelled "threaded": ThreadSanitizer watches the feed and transport threads here.
#include <atomic>
#include <chrono>
#include <cstring>
#include <map>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "daemon/live_view/foxglove_protocol.hpp"
#include "daemon/live_view/live_view.hpp"
#include "tests/support/websocket_client.hpp"

namespace stereod::live_view {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

RectifiedGeometry geometryOf(cv::Size size)
{
    RectifiedGeometry g;
    g.image_size = size;
    g.focal_px = 500.0;
    g.cx_px = size.width / 2.0;
    g.cy_px = size.height / 2.0;
    g.baseline_m = 0.1;
    return g;
}

PublishedFrame frameOf(cv::Size size)
{
    PublishedFrame frame;
    DepthResult& r = frame.result;
    r.left_rectified = cv::Mat(size, CV_8UC1, cv::Scalar(128));
    r.disparity = cv::Mat(size, CV_32FC1, cv::Scalar(20.0f));
    r.confidence = cv::Mat(size, CV_8UC1, cv::Scalar(200));
    r.depth_m = cv::Mat(size, CV_32FC1, cv::Scalar(2.5f));
    r.cloud.assign(1000, CloudPoint{0.1f, 0.2f, 2.5f, 128.0f});
    frame.depth_valid = true;
    frame.stats.range.num_disparities = 64;
    return frame;
}

// Feeds frames from a thread of its own, as the socket server's I/O thread does; each
// reading names its frame (0, 1, ...).
class Producer {
  public:
    Producer(LiveView& view, cv::Size size, std::chrono::milliseconds period)
        : thread_([this, &view, size, period] {
              PublishedFrame frame = frameOf(size);
              while (!stop_.load()) {
                  const uint64_t number = frames_.load();
                  frame.result.frame = number;
                  frame.result.stamp_ns = Clock::now().time_since_epoch().count();
                  view.onFrame(frame, R"({"valid":true,"distance_m":2.5,"frame":)" +
                                          std::to_string(number) + "}");
                  frames_.store(number + 1);
                  std::this_thread::sleep_for(period);
              }
          })
    {
    }
    ~Producer() { stop(); }
    void stop()
    {
        stop_.store(true);
        if (thread_.joinable())
            thread_.join();
    }
    uint64_t frames() const { return frames_.load(); }

  private:
    std::atomic<bool> stop_{false};
    std::atomic<uint64_t> frames_{0};
    std::thread thread_;
};

// The frame a /stereo/nearest message names.
std::optional<uint64_t> readingFrame(const test::WebSocketClient::Message& message)
{
    const std::size_t at = message.payload.find(R"("frame":)");
    if (at == std::string::npos)
        return std::nullopt;
    return std::stoull(message.payload.substr(at + 8));
}

uint32_t subscriptionOf(const test::WebSocketClient::Message& message)
{
    uint32_t id = 0;
    std::memcpy(&id, message.payload.data() + 1, 4); // little-endian, as x86 and arm64
    return id;
}

// Connects, reads serverInfo and advertise, subscribes (subscription id -> channel).
std::unique_ptr<test::WebSocketClient>
subscribe(uint16_t port, const std::map<uint32_t, Channel>& subscriptions, int receive_buffer = 0)
{
    auto client = std::make_unique<test::WebSocketClient>(port, kSubprotocol, receive_buffer);
    for (const char* op : {"serverInfo", "advertise"}) {
        const auto message = client->receive(5s);
        EXPECT_TRUE(message && message->payload.find(op) != std::string::npos) << op;
    }
    std::string request = R"({"op":"subscribe","subscriptions":[)";
    for (const auto& [id, channel] : subscriptions)
        request += (request.back() == '[' ? "" : ",") + std::string(R"({"id":)") +
                   std::to_string(id) + R"(,"channelId":)" + std::to_string(channel) + "}";
    client->sendText(request + "]}");
    return client;
}

TEST(LiveView, ChannelsArriveUnderTheirSubscriptionIdsAtTheirOwnRates)
{
    LiveViewSettings settings;
    settings.port = 0;
    settings.max_rate_hz = 40;
    settings.rate_hz[kPoints] = 4;
    const cv::Size size(64, 48);
    LiveView view(settings, geometryOf(size));
    ASSERT_EQ(view.start(), "");
    auto client = subscribe(view.port(), {{7, kDepth}, {9, kPoints}, {11, kNearest}});
    Producer producer(view, size, 5ms);

    std::map<uint32_t, int> counts;
    const auto start = Clock::now();
    while (Clock::now() - start < 2500ms) {
        const auto message = client->receive(1s);
        ASSERT_TRUE(message) << "no message for 1 s";
        ASSERT_EQ(message->opcode, 2);
        ++counts[subscriptionOf(*message)];
    }
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    EXPECT_EQ(counts.size(), 3u); // only the ids this client chose
    // Never above the rate (with the fifth of an interval allowed for capture jitter),
    // and the points channel, at a tenth of the others' rate, far below them.
    EXPECT_GE(counts[9], 2);
    EXPECT_LE(counts[9], seconds * 4 * 1.25 + 1);
    EXPECT_LE(counts[7], seconds * 40 * 1.25 + 1);
    EXPECT_GE(counts[7], 4 * counts[9]);
    EXPECT_GE(counts[11], 4 * counts[9]);
    const StatusLiveView status = view.status();
    EXPECT_TRUE(status.listening);
    EXPECT_EQ(status.clients, 1u);
    EXPECT_GE(status.messages_sent, static_cast<uint64_t>(counts[7] + counts[9] + counts[11]));
    view.stop();
}

// A client subscribed to big frames that reads slower than they come: frames are
// decimated (counted), every reading still arrives, and none waits behind the frames.
TEST(LiveView, ASlowClientGetsEveryReadingAndFewerFrames)
{
    LiveViewSettings settings;
    settings.port = 0;
    settings.max_rate_hz = 100;
    const cv::Size size(1282, 1110); // Aloe at full size: 5.7 MB of depth a frame
    LiveView view(settings, geometryOf(size));
    ASSERT_EQ(view.start(), "");
    auto client = subscribe(
        view.port(), {{1, kNearest}, {2, kDepth}, {3, kDisparity}, {4, kLeftImage}, {5, kPoints}});
    Producer producer(view, size, 40ms);

    std::vector<uint64_t> readings;
    int frames = 0;
    const auto receive = [&](std::chrono::milliseconds timeout) {
        const auto message = client->receive(timeout);
        if (!message)
            return false;
        if (subscriptionOf(*message) == 1) {
            const auto frame = readingFrame(*message);
            EXPECT_TRUE(frame.has_value()) << message->payload;
            if (frame)
                readings.push_back(*frame);
        } else {
            ++frames;
            // A client that takes its time over each image (a browser drawing it): far
            // slower than four channels of frames come, however fast they are made.
            std::this_thread::sleep_for(150ms);
        }
        return true;
    };
    const auto start = Clock::now();
    while (Clock::now() - start < 4s)
        ASSERT_TRUE(receive(2s)) << "no message for 2 s";
    producer.stop();
    while (receive(1500ms)) {
    }
    ASSERT_FALSE(readings.empty());
    // From the first reading that reached the client (its subscription was not in force
    // for the first frames) to the last frame made: every one, in order.
    for (std::size_t i = 1; i < readings.size(); ++i)
        ASSERT_EQ(readings[i], readings[i - 1] + 1) << "a reading was lost or reordered";
    EXPECT_EQ(readings.back() + 1, producer.frames());
    EXPECT_GE(readings.size(), 20u);
    const StatusLiveView status = view.status();
    EXPECT_EQ(status.readings_sent, readings.size());
    // Frames are what the slow client loses (replaced while waiting for its socket, or
    // already in the mailbox when the feed thread is the slower one, as under TSan), and
    // it is not closed for being slow.
    EXPECT_GE(frames, 5);
    EXPECT_LT(static_cast<uint64_t>(frames), 4 * producer.frames())
        << status.frames_dropped << " frames dropped";
    EXPECT_EQ(status.clients_dropped, 0u);
    EXPECT_FALSE(client->closed());
    view.stop();
}

TEST(LiveView, AClientThatNeverReadsIsClosedOnceAndCountedWhileOthersGoOn)
{
    LiveViewSettings settings;
    settings.port = 0;
    settings.max_rate_hz = 30;
    const cv::Size size(640, 480);
    LiveView view(settings, geometryOf(size));
    ASSERT_EQ(view.start(), "");
    auto reader = subscribe(view.port(), {{1, kNearest}});
    // 2.4 MB a frame it never reads, into a 4 KiB receive buffer.
    auto stuck = subscribe(view.port(), {{1, kDepth}, {2, kDisparity}}, 4096);
    Producer producer(view, size, 33ms);

    int read_before = 0, read_after = 0;
    const auto deadline = Clock::now() + 30s;
    while (view.status().clients_dropped == 0 && Clock::now() < deadline)
        if (reader->receive(1s))
            ++read_before;
    const StatusLiveView dropped = view.status();
    ASSERT_EQ(dropped.clients_dropped, 1u) << "the stuck client was never closed";
    EXPECT_GT(dropped.frames_dropped, 0u);
    // The other client kept its messages all along, and goes on.
    EXPECT_GE(read_before, 100); // five seconds and more of readings at 30 Hz
    const auto after = Clock::now();
    while (Clock::now() - after < 2s)
        if (reader->receive(1s))
            ++read_after;
    EXPECT_GE(read_after, 30);
    EXPECT_FALSE(reader->closed());
    // The stuck one is gone (its socket ends once what was sent is read), and counted once.
    const auto drain_deadline = Clock::now() + 20s;
    while (!stuck->closed() && Clock::now() < drain_deadline)
        stuck->receive(1s);
    EXPECT_TRUE(stuck->closed());
    const StatusLiveView later = view.status();
    EXPECT_EQ(later.clients_dropped, 1u);
    EXPECT_EQ(later.clients, 1u);
    view.stop();
}

// What a client sends that is not a request this server takes: a status message with the
// reason for a text it cannot use, a closed connection for a frame that breaks the
// protocol; never a crash, and the other clients go on.
TEST(LiveView, MalformedMessagesAndFramesGetAnErrorNeverACrash)
{
    LiveViewSettings settings;
    settings.port = 0;
    const cv::Size size(64, 48);
    LiveView view(settings, geometryOf(size));
    ASSERT_EQ(view.start(), "");
    auto witness = subscribe(view.port(), {{1, kNearest}});
    Producer producer(view, size, 20ms);

    // Texts: each answered by a status message (level 2: error) naming the problem.
    auto texts = subscribe(view.port(), {});
    for (const std::string& text :
         std::vector<std::string>{"not json", R"({"op":"subscribe"})",
                                  R"({"op":"subscribe","subscriptions":[{"id":1}]})",
                                  R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":99}]})",
                                  "[1,2,3]", std::string(1000, '{')}) {
        texts->sendText(text);
        std::optional<test::WebSocketClient::Message> reply;
        while ((reply = texts->receive(5s)) && reply->opcode != 1) {
        }
        ASSERT_TRUE(reply) << "no answer to " << text.substr(0, 60);
        EXPECT_NE(reply->payload.find(R"("op":"status")"), std::string::npos) << reply->payload;
        EXPECT_NE(reply->payload.find(R"("level":2)"), std::string::npos) << reply->payload;
    }

    // Frames that break RFC 6455: each ends its own connection.
    const std::string broken[] = {
        std::string("\x81\x05hello", 7),            // a client frame without its mask
        std::string("\x83\x80\x01\x02\x03\x04", 6), // a reserved opcode
        // A text frame announcing 2^62 bytes.
        std::string("\x81\xff\x40\x00\x00\x00\x00\x00\x00\x00\x01\x02\x03\x04", 14),
        std::string("\x01\x80\x01\x02\x03\x04\x81\x80\x01\x02\x03\x04",
                    12), // a fragment, then a new message
    };
    for (const std::string& frame : broken) {
        auto client = subscribe(view.port(), {{1, kNearest}});
        client->sendRaw(frame);
        const auto deadline = Clock::now() + 10s;
        while (!client->closed() && Clock::now() < deadline)
            client->receive(1s);
        EXPECT_TRUE(client->closed()) << "still open after a broken frame";
    }

    // The witness heard readings all along, and the server still serves.
    int heard = 0;
    const auto start = Clock::now();
    while (Clock::now() - start < 1s)
        heard += witness->receive(1s) ? 1 : 0;
    EXPECT_GE(heard, 5);
    EXPECT_FALSE(witness->closed());
    EXPECT_TRUE(view.status().listening);
    view.stop();
}

} // namespace
} // namespace stereod::live_view
