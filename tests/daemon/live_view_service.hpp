#pragma once
// What the live view's end-to-end tests share: a `stereod` replaying a real pair (Tsukuba)
// with its live view on a given address, its status, and plain HTTP exchanges.
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <sys/socket.h>
#include <unistd.h>

#include "base/unique_fd.hpp"
#include "ctl/client.hpp"
#include "pipeline/calibration.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod::test {

using namespace std::chrono_literals;

inline const std::string kClientScripts = std::string(STEREOD_SOURCE_DIR) + "/tests/live_view";

// A port nobody listens on now (bound to 0, then released).
inline uint16_t freePort()
{
    const UniqueFd fd(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd.get(), reinterpret_cast<sockaddr*>(&address), sizeof address);
    socklen_t length = sizeof address;
    ::getsockname(fd.get(), reinterpret_cast<sockaddr*>(&address), &length);
    return ntohs(address.sin_port);
}

// One HTTP exchange on 127.0.0.1:port; the whole answer.
inline std::string httpExchange(uint16_t port, const std::string& request)
{
    const UniqueFd fd(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(port);
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd.get(), reinterpret_cast<sockaddr*>(&address), sizeof address) != 0)
        return {};
    ::send(fd.get(), request.data(), request.size(), MSG_NOSIGNAL);
    std::string answer;
    char buffer[4096];
    ssize_t n = 0;
    while ((n = ::recv(fd.get(), buffer, sizeof buffer, 0)) > 0)
        answer.append(buffer, static_cast<std::size_t>(n));
    return answer;
}

inline std::string httpGet(uint16_t port, const std::string& path)
{
    return httpExchange(port,
                        "GET " + path + " HTTP/1.1\r\nHost: stereod\r\nConnection: close\r\n\r\n");
}

class LiveViewE2e : public ::testing::Test {
  protected:
    void SetUp() override
    {
        recording_ = dir_.file("rec");
        std::filesystem::create_directory(recording_);
        for (int i = 0; i < 3; ++i) {
            std::filesystem::copy_file(tsukubaDir() + "/im3.png",
                                       recording_ + "/left" + std::to_string(i) + ".png");
            std::filesystem::copy_file(tsukubaDir() + "/im4.png",
                                       recording_ + "/right" + std::to_string(i) + ".png");
        }
        calibration_ = dir_.file("calib.yaml");
        saveCalibration(
            makeRectifiedCalibration(cv::Size(384, 288), kTsukubaFocalPx, kTsukubaBaselineM),
            calibration_);
        socket_ = dir_.file("s.sock");
    }

    // `expect_valid`: wait for a valid reading (else for any reading).
    void startService(const std::string& live_view, const std::string& config = {},
                      bool expect_valid = true)
    {
        std::vector<std::string> argv = {stereodPath(), "--replay",    recording_,
                                         "--calib",     calibration_,  "--socket",
                                         socket_,       "--live-view", live_view};
        if (!config.empty()) {
            argv.push_back("--config");
            argv.push_back(config);
        }
        service_ = std::make_unique<ChildProcess>(argv, dir_.file("stereod.log"));
        const auto deadline = std::chrono::steady_clock::now() + 60s;
        while (std::chrono::steady_clock::now() < deadline) {
            try {
                ProtocolClient client(socket_, 2000ms);
                const auto reading = client.request({{"cmd", "distance"}})["reading"];
                if (reading.value("valid", false) ||
                    (!expect_valid && reading.contains("stamp_ns")))
                    return;
            } catch (const std::exception&) {
            }
            std::this_thread::sleep_for(100ms);
        }
        FAIL() << "stereod gave no valid reading within 60 s";
    }

    // The service's depth of its latest pair (snapshot), CV_16UC1 millimetres, 0 = none.
    cv::Mat snapshotDepthMm(cv::Size size)
    {
        ProtocolClient client(socket_, 30000ms);
        const auto snapshot = client.request(
            {{"cmd", "snapshot"}, {"items", nlohmann::ordered_json::array({"depth"})}});
        EXPECT_EQ(snapshot["depth_valid"], true) << snapshot.dump();
        cv::Mat depth_mm(size, CV_16UC1);
        EXPECT_EQ(snapshot["payloads"][0]["bytes"], depth_mm.total() * 2);
        client.readPayload(depth_mm.data, depth_mm.total() * 2);
        return depth_mm;
    }

    nlohmann::ordered_json status()
    {
        ProtocolClient client(socket_, 10000ms);
        return client.request({{"cmd", "status"}})["status"];
    }

    TempDir dir_;
    std::string recording_, calibration_, socket_;
    std::unique_ptr<ChildProcess> service_;
};

} // namespace stereod::test
