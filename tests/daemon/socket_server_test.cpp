// The socket server on its own: a real socket in a temporary directory and a real
// publisher, with a stub in place of the service behind it (daemon/server_backend.hpp).
// The test thread publishes results as the worker would and talks the protocol of
// docs/protocol.md to the server's I/O thread.

#include <chrono>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "capture/frame.hpp"
#include "config/service_config.hpp"
#include "daemon/socket_server.hpp"
#include "tests/support/descriptor_exhaustion.hpp"
#include "tests/support/process.hpp"
#include "tests/support/service_doubles.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::Json;
using test::TempDir;
using test::TestClient;
using test::waitUntil;

// Stands in for the service: a source health the test sets, a fixed service part of
// `status`, and counts of what the server asked. Called on the server's I/O thread.
class StubBackend final : public ServerBackend {
  public:
    SourceHealth sourceHealth(int64_t) override
    {
        std::lock_guard lock(mutex_);
        return health_;
    }

    ServiceStatus serviceStatus(const PublishedFrame* latest, const SourceHealth& health,
                                int64_t) override
    {
        ServiceStatus status;
        status.state = health.down ? "source_down" : latest != nullptr ? "running" : "starting";
        status.source.kind = "stub";
        status.pipeline.matcher = "none";
        return status;
    }

    ReloadOutcome reload() override
    {
        ReloadOutcome outcome;
        outcome.changed = {"publish.readings_max_hz"};
        return outcome;
    }

    void onTick(int64_t) override
    {
        std::lock_guard lock(mutex_);
        ++ticks_;
    }

    void setSourceDown(const std::string& message)
    {
        std::lock_guard lock(mutex_);
        health_.down = true;
        health_.message = message;
    }

    int ticks() const
    {
        std::lock_guard lock(mutex_);
        return ticks_;
    }

  private:
    mutable std::mutex mutex_;
    SourceHealth health_; // guarded by mutex_
    int ticks_ = 0;       // guarded by mutex_
};

class SocketServerTest : public ::testing::Test {
  protected:
    ServerOptions defaultOptions() const
    {
        const ServiceConfig config = defaultConfig();
        ServerOptions options;
        options.socket = config.socket;
        options.socket.path = dir_.file("run/stereod.sock");
        options.publish = config.publish;
        return options;
    }

    // Serves on its own thread; clients may connect as soon as this returns.
    void start(const ServerOptions& options)
    {
        socket_path_ = options.socket.path;
        server_ = std::make_unique<SocketServer>(options, publisher_, backend_);
        thread_ = std::thread([this] { server_->run(); });
    }

    void start() { start(defaultOptions()); }

    void TearDown() override
    {
        if (!server_)
            return;
        server_->requestStop();
        thread_.join();
        server_.reset();
    }

    // Publishes frame `frame` with a valid reading at `distance_m`, captured `age_ms` ago,
    // as the worker does.
    void publish(uint64_t frame, double distance_m, double age_ms = 0.0)
    {
        PublishedFrame& slot = publisher_.writeSlot();
        slot.result.frame = frame;
        slot.result.stamp_ns = monotonicNowNs() - static_cast<int64_t>(age_ms * 1e6);
        // The facts of a processed pair whose region reads distance_m, 90 % valid.
        ReadingFacts& facts = slot.result.facts;
        facts = ReadingFacts{};
        facts.pair = PairOutcome::Processed;
        facts.frame = frame;
        facts.stamp_ns = slot.result.stamp_ns;
        facts.region.region_pixels = 1000;
        facts.region.valid_pixels = 900;
        facts.region.in_range_pixels = 900;
        facts.region.percentile_depth_m = distance_m;
        slot.result.reading = judgeReading(facts);
        slot.depth_mm.create(4, 6, CV_16UC1);
        slot.depth_mm.setTo(1250);
        slot.depth_valid = true;
        slot.reason_message.clear();
        publisher_.publish();
    }

    std::unique_ptr<TestClient> connect() { return std::make_unique<TestClient>(socket_path_); }

    Json statusOf(TestClient& client) { return client.request({{"cmd", "status"}})["status"]; }

    TempDir dir_;
    Publisher publisher_;
    StubBackend backend_;
    std::string socket_path_;
    std::unique_ptr<SocketServer> server_;
    std::thread thread_;
};

TEST_F(SocketServerTest, HelloGivesTheProtocolAndWhetherCalibrated)
{
    ServerOptions options = defaultOptions();
    options.calibrated = false;
    start(options);
    TestClient client(socket_path_);
    const Json reply = client.request({{"cmd", "hello"}, {"id", "a"}});
    EXPECT_EQ(reply["ok"], true);
    EXPECT_EQ(reply["id"], "a");
    EXPECT_EQ(reply["service"], "stereod");
    EXPECT_EQ(reply["protocol"], kProtocolVersion);
    EXPECT_EQ(reply["calibrated"], false);
}

TEST_F(SocketServerTest, DistanceBeforeAnyFrameIsNoFrameYet)
{
    start();
    TestClient client(socket_path_);
    const Json reading = client.request({{"cmd", "distance"}})["reading"];
    EXPECT_EQ(reading["valid"], false);
    EXPECT_TRUE(reading["distance_m"].is_null());
    EXPECT_EQ(reading["reason"]["code"], "no_frame_yet");
    EXPECT_FALSE(reading.contains("stamp_ns"));
}

TEST_F(SocketServerTest, DistanceOfThePublishedFrame)
{
    start();
    publish(7, 1.25);
    TestClient client(socket_path_);
    const Json reply = client.request({{"cmd", "distance"}, {"id", 3}});
    EXPECT_EQ(reply["ok"], true);
    EXPECT_EQ(reply["id"], 3);
    const Json& reading = reply["reading"];
    EXPECT_EQ(reading["valid"], true);
    EXPECT_DOUBLE_EQ(reading["distance_m"].get<double>(), 1.25);
    EXPECT_EQ(reading["frame"], 7);
    EXPECT_GE(reading["age_ms"].get<double>(), 0.0);
}

TEST_F(SocketServerTest, DistanceOlderThanAllowedIsStale)
{
    start();
    publish(1, 1.25, /*age_ms=*/500.0);
    TestClient client(socket_path_);
    const Json reading = client.request({{"cmd", "distance"}, {"max_age_ms", 100}})["reading"];
    EXPECT_EQ(reading["valid"], false);
    EXPECT_EQ(reading["reason"]["code"], "stale");
    EXPECT_NE(reading["reason"]["message"].get<std::string>().find("100.0 ms allowed"),
              std::string::npos)
        << reading;
}

TEST_F(SocketServerTest, DistanceWhenTheSourceIsDownSaysWhy)
{
    backend_.setSourceDown("the stub source is failed: unplugged");
    start();
    publish(1, 1.25);
    TestClient client(socket_path_);
    const Json reading = client.request({{"cmd", "distance"}})["reading"];
    EXPECT_EQ(reading["valid"], false);
    EXPECT_EQ(reading["reason"]["code"], "source_down");
    EXPECT_NE(reading["reason"]["message"].get<std::string>().find("unplugged"), std::string::npos);
}

TEST_F(SocketServerTest, StatusIsTheBackendsPartWithClientsAndReading)
{
    start();
    TestClient client(socket_path_);
    const Json reply = client.request({{"cmd", "status"}});
    ASSERT_EQ(reply["ok"], true);
    const Json& status = reply["status"];
    EXPECT_EQ(status["state"], "starting");
    EXPECT_EQ(status["source"]["kind"], "stub");
    EXPECT_EQ(status["clients"]["connected"], 1);
    EXPECT_EQ(status["clients"]["accepted"], 1);
    EXPECT_EQ(status["reading"]["reason"]["code"], "no_frame_yet");

    publish(4, 0.8);
    const Json running = statusOf(client);
    EXPECT_EQ(running["state"], "running");
    EXPECT_EQ(running["reading"]["frame"], 4);
}

TEST_F(SocketServerTest, ReloadAnswersWithTheBackendsOutcome)
{
    start();
    TestClient client(socket_path_);
    const Json reply = client.request({{"cmd", "reload"}});
    EXPECT_EQ(reply["ok"], true);
    EXPECT_EQ(reply["changed"], Json::array({"publish.readings_max_hz"}));
    EXPECT_EQ(reply["restart_needed"], Json::array());
}

TEST_F(SocketServerTest, SubscriberGetsAnEventPerFrame)
{
    ServerOptions options = defaultOptions();
    options.publish.readings_max_hz = 0.0; // every frame
    start(options);
    TestClient client(socket_path_);
    const Json reply = client.request({{"cmd", "subscribe"}, {"stream", "readings"}});
    ASSERT_EQ(reply["ok"], true);
    EXPECT_EQ(reply["stream"], "readings");
    for (uint64_t frame = 1; frame <= 3; ++frame) {
        publish(frame, 1.0 + static_cast<double>(frame) / 10.0);
        const Json event = client.readJson();
        EXPECT_EQ(event["event"], "reading");
        EXPECT_EQ(event["reading"]["frame"], frame);
        EXPECT_FALSE(event.contains("skipped"));
    }
}

TEST_F(SocketServerTest, DepthSubscriberGetsTheHeaderAndThePayload)
{
    ServerOptions options = defaultOptions();
    options.publish.depth_max_hz = 0.0;
    start(options);
    TestClient client(socket_path_);
    ASSERT_EQ(client.request({{"cmd", "subscribe"}, {"stream", "depth"}})["ok"], true);
    publish(9, 1.25);
    const Json header = client.readJson();
    EXPECT_EQ(header["event"], "depth");
    EXPECT_EQ(header["format"], "u16_mm");
    EXPECT_EQ(header["width"], 6);
    EXPECT_EQ(header["height"], 4);
    ASSERT_EQ(header["bytes"], 48);
    const std::vector<uint8_t> payload = client.readBytes(48);
    EXPECT_EQ(payload[0] | (payload[1] << 8), 1250);
}

TEST_F(SocketServerTest, SourceGoingDownIsToldToReadingsSubscribers)
{
    start();
    publish(1, 1.25);
    TestClient client(socket_path_);
    ASSERT_EQ(client.request({{"cmd", "subscribe"}, {"stream", "readings"}})["ok"], true);
    backend_.setSourceDown("the stub source is failed: unplugged");
    const Json event = client.readJson(); // on the next timer tick
    EXPECT_EQ(event["event"], "reading");
    EXPECT_EQ(event["reading"]["reason"]["code"], "source_down");
}

TEST_F(SocketServerTest, BadJsonIsAnsweredAndTheConnectionStays)
{
    start();
    TestClient client(socket_path_);
    client.send("{\"cmd\": \"hello\"\n");
    const Json reply = client.readJson();
    EXPECT_EQ(reply["ok"], false);
    EXPECT_EQ(reply["error"]["code"], "bad_json");
    EXPECT_EQ(client.request({{"cmd", "fly"}})["error"]["code"], "unknown_command");
    EXPECT_EQ(client.request({{"cmd", "hello"}})["ok"], true);
}

TEST_F(SocketServerTest, AnOversizedRequestIsRefusedAndTheConnectionClosed)
{
    ServerOptions options = defaultOptions();
    options.socket.max_request_bytes = 64;
    start(options);
    TestClient client(socket_path_);
    client.send(std::string(100, 'x') + "\n");
    const Json reply = client.readJson();
    EXPECT_EQ(reply["error"]["code"], "request_too_large");
    EXPECT_TRUE(client.waitForClose());
}

TEST_F(SocketServerTest, TooManyClientsAreTurnedAway)
{
    ServerOptions options = defaultOptions();
    options.socket.max_clients = 2;
    start(options);
    TestClient first(socket_path_);
    TestClient second(socket_path_);
    ASSERT_EQ(first.request({{"cmd", "hello"}})["ok"], true);
    ASSERT_EQ(second.request({{"cmd", "hello"}})["ok"], true);

    TestClient third(socket_path_);
    const Json refusal = third.readJson();
    EXPECT_EQ(refusal["ok"], false);
    EXPECT_EQ(refusal["error"]["code"], "too_many_clients");
    EXPECT_TRUE(third.waitForClose());

    const Json clients = statusOf(first)["clients"];
    EXPECT_EQ(clients["connected"], 2);
    EXPECT_EQ(clients["rejected"], 1);
}

// Issue 23: with the process out of descriptors, a connection waited unanswered while
// accept() failed. It is now taken on the spare descriptor, told why and closed, and the
// next connection after descriptors return is served.
TEST_F(SocketServerTest, OutOfDescriptorsAConnectionIsToldWhyAndClosed)
{
    if (test::sanitizersNeedDescriptors())
        GTEST_SKIP() << "UBSan's vptr check needs descriptors of its own (a pipe)";
    start();
    // Kept open: a connection the server closed meanwhile would free a descriptor.
    const auto first = connect();
    ASSERT_EQ(first->request({{"cmd", "hello"}})["ok"], true);
    UniqueFd waiting(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
    ASSERT_TRUE(waiting);
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    std::snprintf(address.sun_path, sizeof address.sun_path, "%s", socket_path_.c_str());

    test::DescriptorExhaustion exhaustion;
    const int connected =
        ::connect(waiting.get(), reinterpret_cast<sockaddr*>(&address), sizeof address);
    std::string line;
    pollfd p{waiting.get(), POLLIN, 0};
    while (connected == 0 && line.find('\n') == std::string::npos && ::poll(&p, 1, 5000) == 1) {
        char chunk[512];
        const ssize_t n = ::recv(waiting.get(), chunk, sizeof chunk, 0);
        if (n <= 0)
            break;
        line.append(chunk, static_cast<std::size_t>(n));
    }
    exhaustion.release();

    ASSERT_EQ(connected, 0);
    ASSERT_NE(line.find('\n'), std::string::npos) << "no answer: \"" << line << "\"";
    const Json refusal = Json::parse(line.substr(0, line.find('\n')));
    EXPECT_EQ(refusal["error"]["code"], "too_many_clients") << line;
    EXPECT_NE(refusal["error"]["message"].get<std::string>().find("out of file descriptors"),
              std::string::npos)
        << line;
    // Descriptors are back: a client gets in again once the accept loop's back-off (100 ms
    // at first) has passed; one that connects within it is refused as the others were.
    std::unique_ptr<TestClient> next;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (!next && std::chrono::steady_clock::now() < deadline) {
        try {
            auto client = std::make_unique<TestClient>(socket_path_);
            if (client->request({{"cmd", "hello"}})["ok"] == true)
                next = std::move(client);
        } catch (const std::exception&) {
            // refused during the back-off
        }
        if (!next)
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ASSERT_TRUE(next) << "no client got in within 5 s of the descriptors' return";
    EXPECT_GE(statusOf(*next)["clients"]["rejected"].get<int>(), 1);
}

TEST_F(SocketServerTest, APeerThatHangsUpIsClosedAndItsPlaceFreed)
{
    ServerOptions options = defaultOptions();
    options.socket.max_clients = 2;
    start(options);
    TestClient stays(socket_path_);
    {
        TestClient leaves(socket_path_);
        ASSERT_EQ(leaves.request({{"cmd", "hello"}})["ok"], true);
        ASSERT_EQ(statusOf(stays)["clients"]["connected"], 2);
    }
    EXPECT_TRUE(waitUntil([&] { return statusOf(stays)["clients"]["connected"] == 1; }));
    // The place is free again.
    TestClient next(socket_path_);
    EXPECT_EQ(next.request({{"cmd", "hello"}})["ok"], true);
}

TEST_F(SocketServerTest, APeerOutsideTheAllowListsIsRefused)
{
    ServerOptions options = defaultOptions();
    options.socket.allow_uids = {static_cast<uint32_t>(::getuid()) + 1};
    options.socket.allow_gids = {static_cast<uint32_t>(::getgid()) + 1};
    start(options);
    TestClient client(socket_path_);
    const Json refusal = client.readJson();
    EXPECT_EQ(refusal["ok"], false);
    EXPECT_EQ(refusal["error"]["code"], "not_allowed");
    EXPECT_NE(
        refusal["error"]["message"].get<std::string>().find("uid " + std::to_string(::getuid())),
        std::string::npos);
    EXPECT_TRUE(client.waitForClose());
}

TEST_F(SocketServerTest, APeerInTheAllowListIsServed)
{
    ServerOptions options = defaultOptions();
    options.socket.allow_uids = {static_cast<uint32_t>(::getuid())};
    start(options);
    TestClient client(socket_path_);
    EXPECT_EQ(client.request({{"cmd", "hello"}})["ok"], true);
    EXPECT_EQ(statusOf(client)["clients"]["not_allowed"], 0);
}

TEST_F(SocketServerTest, TheTimerTicksTheBackend)
{
    start();
    EXPECT_TRUE(waitUntil([&] { return backend_.ticks() >= 2; }));
}

} // namespace
} // namespace stereod
