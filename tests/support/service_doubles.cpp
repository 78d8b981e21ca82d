#include "tests/support/service_doubles.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include <opencv2/imgproc.hpp>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

namespace stereod::test {

namespace {

// Pairs in flight: the ring (4 by default), the one the worker holds, the one being filled.
constexpr std::size_t kPoolPairs = 8;

} // namespace

FakeSource::FakeSource(cv::Mat left, cv::Mat right)
    : left_(std::move(left)), right_(std::move(right)), size_(left_.size()),
      pool_(2 * kPoolPairs, size_), small_pool_(4, cv::Size(size_.width / 2, size_.height / 2))
{
    cv::resize(left_, small_left_, small_pool_.frameSize());
    cv::resize(right_, small_right_, small_pool_.frameSize());
}

FakeSource::~FakeSource()
{
    stop();
}

int FakeSource::start(PairRing& ring)
{
    ring_ = &ring;
    stop_.store(false);
    {
        std::lock_guard lock(mutex_);
        state_ = SourceState::Running;
    }
    thread_ = std::thread([this] { run(); });
    return 0;
}

void FakeSource::stop() noexcept
{
    stop_.store(true);
    wake();
    // A push blocked in pushWait() wakes only when the ring stops.
    if (ring_ != nullptr)
        ring_->stop();
    if (thread_.joinable())
        thread_.join();
    ring_ = nullptr; // borrowed until stop() returns
    std::lock_guard lock(mutex_);
    if (state_ == SourceState::Running)
        state_ = SourceState::Stopped;
}

SourceStatus FakeSource::status() const
{
    SourceStatus status;
    status.kind = "fake";
    std::lock_guard lock(mutex_);
    status.state = state_;
    status.last_error = last_error_;
    status.pairs = delivered_.load();
    for (const char* name : {"left", "right"}) {
        CameraStatus camera;
        camera.name = name;
        camera.state = state_;
        camera.frames = status.pairs;
        status.cameras.push_back(camera);
    }
    return status;
}

void FakeSource::deliver(uint64_t pairs)
{
    budget_.fetch_add(pairs);
    wake();
}

void FakeSource::deliverContinuously(bool on)
{
    continuous_.store(on);
    wake();
}

void FakeSource::fail(const std::string& message)
{
    std::lock_guard lock(mutex_);
    state_ = SourceState::Failed;
    last_error_ = message;
}

void FakeSource::wake()
{
    wake_.fetch_add(1);
    wake_.notify_all();
}

void FakeSource::run()
{
    while (!stop_.load()) {
        const uint32_t seen = wake_.load();
        if (budget_.load() == 0 && !continuous_.load()) {
            wake_.wait(seen);
            continue;
        }
        if (!pushOne())
            return;
    }
}

bool FakeSource::pushOne()
{
    const bool small = wrong_size_.load();
    FramePool& pool = small ? small_pool_ : pool_;
    FrameHandle left = pool.acquire();
    FrameHandle right = pool.acquire();
    if (!left || !right) {
        // Every buffer is queued or held by the worker: wait for one to come back.
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        return !stop_.load();
    }
    (small ? small_left_ : left_).copyTo(left->image);
    (small ? small_right_ : right_).copyTo(right->image);
    const uint64_t index = delivered_.load();
    left->stamp_ns = monotonicNowNs();
    right->stamp_ns = left->stamp_ns + skew_ns_.load();
    left->sequence = right->sequence = index;
    StereoPair pair;
    pair.left = std::move(left);
    pair.right = std::move(right);
    pair.index = index;
    if (!ring_->pushWait(std::move(pair)))
        return false;
    delivered_.fetch_add(1);
    if (!continuous_.load() && budget_.load() > 0)
        budget_.fetch_sub(1);
    return true;
}

TestClient::TestClient(const std::string& socket_path)
{
    fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0)
        throw std::runtime_error(std::string("socket: ") + std::strerror(errno));
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    std::strncpy(address.sun_path, socket_path.c_str(), sizeof address.sun_path - 1);
    if (::connect(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0) {
        const int error = errno;
        ::close(fd_);
        throw std::runtime_error("connect " + socket_path + ": " + std::strerror(error));
    }
}

TestClient::~TestClient()
{
    if (fd_ >= 0)
        ::close(fd_);
}

void TestClient::send(std::string_view bytes)
{
    while (!bytes.empty()) {
        const ssize_t sent = ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL);
        if (sent < 0) {
            if (errno == EINTR)
                continue;
            throw std::runtime_error(std::string("send: ") + std::strerror(errno));
        }
        bytes.remove_prefix(static_cast<std::size_t>(sent));
    }
}

void TestClient::sendJson(const Json& request)
{
    send(request.dump() + "\n");
}

bool TestClient::waitReadable()
{
    pollfd descriptor{fd_, POLLIN, 0};
    for (;;) {
        const int ready = ::poll(&descriptor, 1, static_cast<int>(kWait.count()));
        if (ready < 0 && errno == EINTR)
            continue;
        return ready > 0;
    }
}

long TestClient::receive()
{
    if (!waitReadable())
        throw std::runtime_error("no data from the service within the wait limit");
    char chunk[65536];
    for (;;) {
        const ssize_t got = ::recv(fd_, chunk, sizeof chunk, 0);
        if (got < 0 && errno == EINTR)
            continue;
        if (got > 0)
            buffer_.append(chunk, static_cast<std::size_t>(got));
        return got;
    }
}

std::string TestClient::readLine()
{
    for (;;) {
        const std::size_t newline = buffer_.find('\n');
        if (newline != std::string::npos) {
            std::string line = buffer_.substr(0, newline);
            buffer_.erase(0, newline + 1);
            return line;
        }
        const long got = receive();
        if (got == 0)
            throw std::runtime_error("the service closed the connection");
        if (got < 0)
            throw std::runtime_error(std::string("recv: ") + std::strerror(errno));
    }
}

Json TestClient::readJson()
{
    return Json::parse(readLine());
}

Json TestClient::request(const Json& request)
{
    sendJson(request);
    return readJson();
}

std::vector<uint8_t> TestClient::readBytes(std::size_t count)
{
    while (buffer_.size() < count) {
        const long got = receive();
        if (got <= 0)
            throw std::runtime_error("the connection ended inside a payload");
    }
    std::vector<uint8_t> bytes(buffer_.begin(),
                               buffer_.begin() + static_cast<std::ptrdiff_t>(count));
    buffer_.erase(0, count);
    return bytes;
}

bool TestClient::waitForClose()
{
    for (;;) {
        if (!waitReadable())
            return false;
        const long got = receive();
        buffer_.clear();
        if (got == 0 || (got < 0 && errno == ECONNRESET))
            return true;
        if (got < 0)
            return false;
    }
}

std::unique_ptr<TestClient> connectWhenListening(ChildProcess& service,
                                                 const std::string& socket_path)
{
    std::unique_ptr<TestClient> client;
    waitUntil([&] {
        if (!service.running())
            return true;
        try {
            client = std::make_unique<TestClient>(socket_path);
            return true;
        } catch (const std::exception&) {
            return false;
        }
    });
    return client;
}

NotifySocket::NotifySocket(const std::string& path)
{
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    std::strncpy(address.sun_path, path.c_str(), sizeof address.sun_path - 1);
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0 || ::bind(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0)
        throw std::runtime_error("cannot bind the notify socket " + path);
}

NotifySocket::~NotifySocket()
{
    ::close(fd_);
}

std::optional<NotifySocket::Message> NotifySocket::next(std::chrono::milliseconds limit)
{
    pollfd waiting{fd_, POLLIN, 0};
    if (::poll(&waiting, 1, static_cast<int>(limit.count())) <= 0)
        return std::nullopt;
    char buffer[4096];
    const ssize_t got = ::recv(fd_, buffer, sizeof buffer, 0);
    if (got < 0)
        return std::nullopt;
    Message message{Clock::now(), std::string(buffer, static_cast<std::size_t>(got))};
    received_.push_back(message);
    return message;
}

std::optional<NotifySocket::Message> NotifySocket::waitFor(const std::string& needle,
                                                           std::chrono::milliseconds limit)
{
    const auto deadline = Clock::now() + limit;
    while (Clock::now() < deadline) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
        std::optional<Message> message = next(std::max(left, std::chrono::milliseconds(1)));
        if (message && message->text.find(needle) != std::string::npos)
            return message;
    }
    return std::nullopt;
}

std::vector<NotifySocket::Message> NotifySocket::collect(std::chrono::milliseconds span)
{
    std::vector<Message> messages;
    const auto deadline = Clock::now() + span;
    while (Clock::now() < deadline) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
        if (std::optional<Message> message = next(std::max(left, std::chrono::milliseconds(1))))
            messages.push_back(*message);
    }
    return messages;
}

std::string NotifySocket::all() const
{
    std::string text;
    for (const Message& message : received_)
        text += "[" + message.text + "]\n";
    return text;
}

ScopedEnv::ScopedEnv(const std::string& name, const std::string& value) : name_(name)
{
    ::setenv(name.c_str(), value.c_str(), 1);
}

ScopedEnv::~ScopedEnv()
{
    ::unsetenv(name_.c_str());
}

} // namespace stereod::test
