// `stereod` as systemd runs it, without systemd: a datagram socket of the test stands in
// for systemd's notify socket (NOTIFY_SOCKET, WATCHDOG_USEC), and a listening socket
// passed as fd 3 with LISTEN_FDS/LISTEN_PID stands in for socket activation.
//
//  - READY=1 once the socket listens and the first pair arrived; STATUS= lines; WATCHDOG=1
//    pings; SIGHUP reload (RELOADING=1, READY=1, the new settings in force, clients kept)
//    and a refused reload (the reason in STATUS= and in the reply); SIGTERM (STOPPING=1,
//    exit 0, socket file removed).
//  - A pipeline stuck in one pair (a full-size Aloe pair with 1024 disparities: seconds of
//    matching, far longer than the watchdog interval): the pings stop; SIGTERM mid-match
//    still ends the service at once with exit 0.
//  - Socket activation: the service serves on the socket it was handed and leaves the
//    file (systemd's) in place.

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <fcntl.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include "pipeline/calibration.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/service_doubles.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::ChildProcess;
using test::Json;
using test::NotifySocket;
using test::ScopedEnv;
using test::stereodPath;
using test::TempDir;
using test::TestClient;
using test::waitUntil;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

const std::string kTsukuba = test::tsukubaDir();
const std::string kSamples = test::opencvSamplesDir();

sockaddr_un unixAddress(const std::string& path)
{
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    std::strncpy(address.sun_path, path.c_str(), sizeof address.sun_path - 1);
    return address;
}

std::string readFile(const std::string& path)
{
    std::ifstream file(path);
    return std::string(std::istreambuf_iterator<char>(file), {});
}

std::size_t count(const std::vector<NotifySocket::Message>& messages, const std::string& needle)
{
    std::size_t n = 0;
    for (const NotifySocket::Message& message : messages)
        n += message.text.find(needle) != std::string::npos ? 1 : 0;
    return n;
}

class StereodUnderSystemd : public ::testing::Test {
  protected:
    void SetUp() override
    {
        socket_ = dir_.file("run/stereod.sock");
        log_ = dir_.file("stereod.log");
    }

    // A folder of one pair, by links.
    std::string replayOf(const std::string& left, const std::string& right)
    {
        const std::string folder = dir_.file("rec");
        std::filesystem::create_directory(folder);
        std::filesystem::create_symlink(left, folder + "/left0.png");
        std::filesystem::create_symlink(right, folder + "/right0.png");
        return folder;
    }

    std::unique_ptr<TestClient> connect(ChildProcess& service)
    {
        std::unique_ptr<TestClient> client = test::connectWhenListening(service, socket_);
        EXPECT_TRUE(client) << "stereod exited during start-up:\n" << readFile(log_);
        return client;
    }

    TempDir dir_;
    std::string socket_;
    std::string log_;
};

TEST_F(StereodUnderSystemd, NotifiesReadyStatusWatchdogReloadAndStop)
{
    const std::string replay = replayOf(kTsukuba + "/im3.png", kTsukuba + "/im4.png");
    const std::string calibration = dir_.file("tsukuba.yaml");
    saveCalibration(makeRectifiedCalibration(cv::Size(384, 288), 615.0, 0.013), calibration);
    const std::string config = dir_.file("stereod.yaml");
    const auto write_config = [&](const std::string& extra) {
        std::ofstream(config) << "source:\n  replay:\n    path: " << replay << "\n    fps: 20\n"
                              << "calibration: " << calibration << "\n"
                              << "socket:\n  path: " << socket_ << "\n"
                              << extra;
    };
    write_config("matcher:\n  algorithm: sgbm\n");

    NotifySocket notify(dir_.file("notify"));
    ScopedEnv notify_socket("NOTIFY_SOCKET", dir_.file("notify"));
    ScopedEnv watchdog("WATCHDOG_USEC", "400000");
    ChildProcess service({stereodPath(), "--config", config}, log_);

    // READY=1: the socket listens and a pair has arrived by then.
    const std::optional<NotifySocket::Message> ready = notify.waitFor("READY=1", 30s);
    ASSERT_TRUE(ready) << notify.all() << readFile(log_);
    EXPECT_TRUE(std::filesystem::exists(socket_));
    std::unique_ptr<TestClient> client = connect(service);
    ASSERT_TRUE(client);
    EXPECT_GE(client->request({{"cmd", "status"}})["status"]["source"]["pairs"].get<uint64_t>(),
              1u);

    // Pings every quarter of the interval (100 ms) while the worker keeps up, and a
    // STATUS= line a person can read.
    const std::vector<NotifySocket::Message> running = notify.collect(2500ms);
    EXPECT_GE(count(running, "WATCHDOG=1"), 4u) << notify.all();
    ASSERT_TRUE(notify.waitFor("STATUS=running: ", 5s)) << notify.all();
    const std::string all = notify.all();
    EXPECT_NE(all.find(" fps, frame "), std::string::npos) << all;
    EXPECT_NE(all.find("left "), std::string::npos) << all;

    // SIGHUP: a live change (the matcher and the publishing rate) applied, the
    // connection kept.
    write_config("matcher:\n  algorithm: bm\npublish:\n  readings_max_hz: 5\n");
    service.sendSignal(SIGHUP);
    ASSERT_TRUE(notify.waitFor("RELOADING=1", 10s)) << notify.all();
    ASSERT_TRUE(notify.waitFor("READY=1", 10s)) << notify.all();
    Json status;
    EXPECT_TRUE(waitUntil([&] {
        status = client->request({{"cmd", "status"}})["status"];
        return status["pipeline"]["matcher"] == "bm";
    })) << status.dump();

    // An invalid file: refused, the running configuration stays, and STATUS= says why.
    write_config("matcher:\n  algorithm: bm\n  block_size: 4\n");
    service.sendSignal(SIGHUP);
    const std::optional<NotifySocket::Message> refused = notify.waitFor("reload refused", 10s);
    ASSERT_TRUE(refused) << notify.all();
    EXPECT_NE(refused->text.find("matcher.block_size"), std::string::npos) << refused->text;
    EXPECT_NE(refused->text.find("STATUS="), std::string::npos) << refused->text;
    const Json reply = client->request({{"cmd", "reload"}});
    EXPECT_EQ(reply["ok"], false) << reply.dump();
    EXPECT_EQ(client->request({{"cmd", "status"}})["status"]["pipeline"]["matcher"], "bm");
    EXPECT_NE(readFile(log_).find("reload refused"), std::string::npos);

    // SIGTERM: STOPPING=1, exit 0, the socket file gone.
    service.sendSignal(SIGTERM);
    const std::optional<int> exit_status = service.waitFor(10s);
    ASSERT_TRUE(exit_status.has_value());
    EXPECT_TRUE(WIFEXITED(*exit_status) && WEXITSTATUS(*exit_status) == 0) << readFile(log_);
    EXPECT_TRUE(notify.waitFor("STOPPING=1", 1s)) << notify.all();
    EXPECT_FALSE(std::filesystem::exists(socket_));
}

TEST_F(StereodUnderSystemd, StuckPipelineStopsThePingsAndSigtermStillStopsAtOnce)
{
    // Aloe at twice its full size (2564x2220) with 1024 disparities: seconds of matching
    // per pair (about 5 s on a 2-core x86 machine), where the watchdog interval is 0.2 s.
    const cv::Size size(2564, 2220);
    for (const char* side : {"L", "R"}) {
        cv::Mat image = cv::imread(kSamples + "/aloe" + side + ".jpg", cv::IMREAD_GRAYSCALE);
        ASSERT_FALSE(image.empty());
        cv::resize(image, image, size, 0, 0, cv::INTER_LINEAR);
        ASSERT_TRUE(cv::imwrite(dir_.file(std::string("big") + side + ".png"), image));
    }
    const std::string replay = replayOf(dir_.file("bigL.png"), dir_.file("bigR.png"));
    const std::string calibration = dir_.file("aloe.yaml");
    saveCalibration(makeRectifiedCalibration(size, 3740.0, 0.160), calibration);
    const std::string config = dir_.file("stereod.yaml");
    std::ofstream(config) << "source:\n  replay:\n    path: " << replay << "\n"
                          << "calibration: " << calibration << "\n"
                          << "socket:\n  path: " << socket_ << "\n"
                          << "matcher:\n  algorithm: sgbm\n  num_disparities: 1024\n"
                          << "  max_num_disparities: 1024\n";

    NotifySocket notify(dir_.file("notify"));
    ScopedEnv notify_socket("NOTIFY_SOCKET", dir_.file("notify"));
    ScopedEnv watchdog("WATCHDOG_USEC", "200000");
    ChildProcess service({stereodPath(), "--config", config}, log_);
    ASSERT_TRUE(notify.waitFor("READY=1", 30s)) << notify.all() << readFile(log_);
    std::unique_ptr<TestClient> client = connect(service);
    ASSERT_TRUE(client);

    // From 0.3 s after the worker took the pair on (the pings stop after 0.2 s), for
    // 0.6 s (pings would come every 0.1 s): no ping.
    notify.collect(300ms);
    const std::vector<NotifySocket::Message> stuck = notify.collect(600ms);
    const Json status = client->request({{"cmd", "status"}})["status"];
    // Still inside the first pair: none finished, one taken.
    ASSERT_EQ(status["pipeline"]["frames"], 0) << status.dump();
    ASSERT_GE(status["source"]["pairs"].get<uint64_t>(), 1u) << status.dump();
    EXPECT_EQ(count(stuck, "WATCHDOG=1"), 0u) << notify.all();

    // SIGTERM mid-match: the service does not wait the seconds the pair still needs.
    const auto signalled = Clock::now();
    service.sendSignal(SIGTERM);
    const std::optional<int> exit_status = service.waitFor(10s);
    const double stop_s = std::chrono::duration<double>(Clock::now() - signalled).count();
    ASSERT_TRUE(exit_status.has_value());
    EXPECT_TRUE(WIFEXITED(*exit_status) && WEXITSTATUS(*exit_status) == 0) << readFile(log_);
    EXPECT_FALSE(std::filesystem::exists(socket_));
    EXPECT_TRUE(client->waitForClose());
    const std::string log = readFile(log_);
    EXPECT_NE(log.find("stopping without the worker"), std::string::npos) << log;
    // The pair alone would take seconds more; the stop budget is 0.7 s. The bound is
    // loose for loaded machines; the log above proves the stop did not wait.
    EXPECT_LT(stop_s, 2.0) << log;
    std::cout << "stop mid-match took " << stop_s << " s\n";
}

// A child that gets `listen_fd` as fd 3 with LISTEN_FDS=1 and LISTEN_PID=its own pid,
// as systemd starts a socket-activated service. Its stderr goes to `log_path`.
pid_t spawnActivated(const std::vector<std::string>& argv, int listen_fd,
                     const std::string& log_path)
{
    // Everything the child needs is prepared before fork(): after it, only
    // async-signal-safe calls.
    std::vector<std::string> env_strings;
    for (char** entry = environ; *entry != nullptr; ++entry) {
        const std::string text = *entry;
        if (text.rfind("LISTEN_", 0) != 0 && text.rfind("NOTIFY_SOCKET=", 0) != 0)
            env_strings.push_back(text);
    }
    env_strings.push_back("LISTEN_FDS=1");
    std::string listen_pid = "LISTEN_PID=0000000000";
    std::vector<char*> env;
    for (std::string& text : env_strings)
        env.push_back(text.data());
    env.push_back(listen_pid.data());
    env.push_back(nullptr);
    std::vector<std::string> arg_strings = argv;
    std::vector<char*> args;
    for (std::string& text : arg_strings)
        args.push_back(text.data());
    args.push_back(nullptr);
    const int log_fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);

    const pid_t pid = ::fork();
    if (pid != 0)
        return pid;
    // The child: its pid into LISTEN_PID (digits written by hand), fd 3, exec.
    char* digits = listen_pid.data() + std::strlen("LISTEN_PID=");
    unsigned long value = static_cast<unsigned long>(::getpid());
    char reversed[16];
    int n = 0;
    do {
        reversed[n++] = static_cast<char>('0' + value % 10);
        value /= 10;
    } while (value > 0);
    for (int i = 0; i < n; ++i)
        digits[i] = reversed[n - 1 - i];
    digits[n] = '\0';
    if (::dup2(listen_fd, 3) < 0 || ::dup2(log_fd, STDERR_FILENO) < 0)
        ::_exit(126);
    ::execve(args[0], args.data(), env.data());
    ::_exit(127);
}

TEST_F(StereodUnderSystemd, SocketActivationServesOnTheHandedSocketAndLeavesItsFile)
{
    const std::string replay = replayOf(kTsukuba + "/im3.png", kTsukuba + "/im4.png");
    const std::string calibration = dir_.file("tsukuba.yaml");
    saveCalibration(makeRectifiedCalibration(cv::Size(384, 288), 615.0, 0.013), calibration);

    // What systemd does for stereod.socket: bind, listen, keep the file.
    std::filesystem::create_directories(dir_.file("run"));
    const int listen_fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    const sockaddr_un address = unixAddress(socket_);
    ASSERT_EQ(::bind(listen_fd, reinterpret_cast<const sockaddr*>(&address), sizeof address), 0);
    ASSERT_EQ(::listen(listen_fd, 16), 0);
    struct stat before {};
    ASSERT_EQ(::lstat(socket_.c_str(), &before), 0);

    const pid_t pid = spawnActivated(
        {stereodPath(), "--replay", replay, "--calib", calibration, "--socket", socket_}, listen_fd,
        log_);
    ASSERT_GT(pid, 0);
    {
        // Served on the handed socket (the log says so), the same file as before.
        TestClient client(socket_);
        EXPECT_EQ(client.request({{"cmd", "hello"}})["ok"], true);
        Json reading;
        EXPECT_TRUE(waitUntil([&] {
            reading = client.request({{"cmd", "distance"}})["reading"];
            return reading["valid"] == true;
        })) << reading.dump();
    }
    EXPECT_NE(readFile(log_).find("socket from systemd"), std::string::npos) << readFile(log_);

    ::kill(pid, SIGTERM);
    int status = 0;
    const bool exited = waitUntil([&] { return ::waitpid(pid, &status, WNOHANG) == pid; }, 10000ms);
    if (!exited) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &status, 0);
    }
    ASSERT_TRUE(exited) << readFile(log_);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << readFile(log_);
    // The file belongs to systemd: still there, still the same socket, still listening
    // (systemd would start the service again on the next connection).
    struct stat after {};
    ASSERT_EQ(::lstat(socket_.c_str(), &after), 0) << "the service removed systemd's socket";
    EXPECT_EQ(after.st_ino, before.st_ino);
    const int probe = ::socket(AF_UNIX, SOCK_STREAM, 0);
    EXPECT_EQ(::connect(probe, reinterpret_cast<const sockaddr*>(&address), sizeof address), 0);
    ::close(probe);
    ::close(listen_fd);
}

} // namespace
} // namespace stereod
