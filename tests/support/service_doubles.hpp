#pragma once
// Test doubles and tools for the service tests: a frame source that delivers real image
// pairs on demand, and a blocking protocol client with time limits. (Temporary
// directories and child processes: tests/support/.)

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "capture/frame_pool.hpp"
#include "capture/frame_source.hpp"
#include "tests/support/process.hpp"

namespace stereod::test {

using Json = nlohmann::ordered_json;

// A frame source that delivers copies of one real image pair, only when told to: a given
// number of pairs, or continuously. Pairs go into the ring with pushWait() (nothing is
// dropped), stamped with CLOCK_MONOTONIC at delivery; the right stamp is the left one
// plus a chosen skew. It can also deliver frames of a wrong size and pretend to fail.
//
// Thread-safety: as FrameSource; the controls (deliver(), setSkewNs(), ...) from any
// thread.
class FakeSource final : public FrameSource {
  public:
    FakeSource(cv::Mat left, cv::Mat right);
    ~FakeSource() override;

    int start(PairRing& ring) override;
    void stop() noexcept override;
    SourceStatus status() const override;
    cv::Size frameSize() const override { return size_; }
    // It waits for room (pushWait()): every pair it delivers is processed.
    bool keepsEveryPair() const noexcept override { return true; }

    // Delivers `pairs` more pairs, as fast as the ring takes them.
    void deliver(uint64_t pairs);
    // Keeps delivering until switched off.
    void deliverContinuously(bool on);
    // Right minus left capture time of the pairs to come.
    void setSkewNs(int64_t skew_ns) { skew_ns_.store(skew_ns); }
    // The pairs to come are half the size of the calibrated frames.
    void setWrongSize(bool on) { wrong_size_.store(on); }
    // Enters state Failed with this error, as a vanished device would.
    void fail(const std::string& message);
    // Pairs pushed into the ring so far.
    uint64_t delivered() const { return delivered_.load(); }

  private:
    void run();
    bool pushOne();
    void wake();

    cv::Mat left_, right_, small_left_, small_right_;
    cv::Size size_;
    FramePool pool_;
    FramePool small_pool_;
    PairRing* ring_ = nullptr;
    std::thread thread_;
    std::atomic<uint64_t> budget_{0};
    std::atomic<bool> continuous_{false};
    std::atomic<bool> stop_{false};
    std::atomic<uint32_t> wake_{0};
    std::atomic<int64_t> skew_ns_{0};
    std::atomic<bool> wrong_size_{false};
    std::atomic<uint64_t> delivered_{0};
    mutable std::mutex mutex_;
    SourceState state_ = SourceState::Stopped; // guarded by mutex_
    std::string last_error_;                   // guarded by mutex_
};

// A blocking client of the service's socket; every wait is bounded (a test that hangs
// tells nothing), and a bound reached fails the test with what was awaited.
class TestClient {
  public:
    static constexpr std::chrono::milliseconds kWait{30000};

    explicit TestClient(const std::string& socket_path);
    ~TestClient();
    TestClient(const TestClient&) = delete;
    TestClient& operator=(const TestClient&) = delete;

    void send(std::string_view bytes);
    void sendJson(const Json& request);
    // One line without its newline. Throws std::runtime_error on EOF, error or timeout.
    std::string readLine();
    Json readJson();
    // Sends a request and reads one line back.
    Json request(const Json& request);
    std::vector<uint8_t> readBytes(std::size_t count);
    // Reads and drops everything until the service closes the connection: true on EOF or
    // a reset, false when the wait limit passes first.
    bool waitForClose();
    int fd() const { return fd_; }

  private:
    // Waits for input; false when the wait limit passes first.
    bool waitReadable();
    // Reads what is there into buffer_; 0 on EOF, -1 on error.
    long receive();

    int fd_ = -1;
    std::string buffer_;
};

// Stands in for systemd's notify socket (NOTIFY_SOCKET): a datagram socket bound at a
// path that keeps what the service sends, with the time each message arrived.
class NotifySocket {
  public:
    using Clock = std::chrono::steady_clock;
    struct Message {
        Clock::time_point at;
        std::string text;
    };

    // Throws std::runtime_error when it cannot bind `path`.
    explicit NotifySocket(const std::string& path);
    ~NotifySocket();
    NotifySocket(const NotifySocket&) = delete;
    NotifySocket& operator=(const NotifySocket&) = delete;

    // The next message, or nullopt when none comes within `limit`.
    std::optional<Message> next(std::chrono::milliseconds limit);
    // Reads until a message contains `needle`; nullopt when `limit` passes first.
    std::optional<Message> waitFor(const std::string& needle, std::chrono::milliseconds limit);
    // Everything received for `span`.
    std::vector<Message> collect(std::chrono::milliseconds span);
    // Every message received so far, one per line in brackets.
    std::string all() const;

  private:
    int fd_ = -1;
    std::vector<Message> received_;
};

// Sets an environment variable while it lives (for the service it starts, in process or
// as a child), and unsets it after.
class ScopedEnv {
  public:
    ScopedEnv(const std::string& name, const std::string& value);
    ~ScopedEnv();
    ScopedEnv(const ScopedEnv&) = delete;
    ScopedEnv& operator=(const ScopedEnv&) = delete;

  private:
    std::string name_;
};

// Polls `condition` every few milliseconds until it holds or `limit` passes.
template <typename Condition>
bool waitUntil(Condition condition, std::chrono::milliseconds limit = TestClient::kWait)
{
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (!condition()) {
        if (std::chrono::steady_clock::now() > deadline)
            return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return true;
}

// A client of the service `service` started, once its socket answers; nullptr when the
// service exits first or the wait limit passes.
std::unique_ptr<TestClient> connectWhenListening(ChildProcess& service,
                                                 const std::string& socket_path);

} // namespace stereod::test
