#pragma once
// What the live view's end-to-end tests share: a `stereod` replaying a real pair (Tsukuba)
// with its live view on a given address, its addresses with the token (`view`), its
// status, and plain HTTP exchanges (tests/support/http_client.hpp).
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
#include "tests/support/http_client.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod::test {

using namespace std::chrono_literals;

inline const std::string kClientScripts = std::string(STEREOD_SOURCE_DIR) + "/tests/live_view";

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
        std::vector<std::string> argv = launcher_;
        for (const std::string& arg :
             {stereodPath(), std::string("--replay"), recording_, std::string("--calib"),
              calibration_, std::string("--socket"), socket_, std::string("--live-view"),
              live_view})
            argv.push_back(arg);
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
                    (!expect_valid && reading.contains("stamp_ns"))) {
                    readLinks();
                    return;
                }
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

    // The live view's addresses with the token, as `stereoctl view` gets them.
    void readLinks()
    {
        ProtocolClient client(socket_, 10000ms);
        const auto links = client.request({{"cmd", "view"}});
        page_ = links.value("page", std::string());
        websocket_ = links.value("websocket", std::string());
        const std::size_t at = page_.find("?token=");
        token_ = at == std::string::npos ? std::string() : page_.substr(at + 7);
    }

    nlohmann::ordered_json status()
    {
        ProtocolClient client(socket_, 10000ms);
        return client.request({{"cmd", "status"}})["status"];
    }

    TempDir dir_;
    std::string recording_, calibration_, socket_;
    std::string page_, websocket_, token_; // the live view's, once the service runs
    std::vector<std::string> launcher_;    // runs stereod (e.g. prlimit ... --), or empty
    std::unique_ptr<ChildProcess> service_;
};

} // namespace stereod::test
