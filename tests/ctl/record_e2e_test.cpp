// Raw frames from the service, its uncalibrated mode, and `stereoctl record`, as separate
// processes (the fixture: tests/ctl/record_e2e_fixture.hpp).

#include <algorithm>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <signal.h>

#include "capture/frame_source.hpp"
#include "ctl/client.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/calibration_formats.hpp"
#include "replay/mcap_recording.hpp"
#include "replay/recording.hpp"
#include "replay/replay_source.hpp"
#include "tests/ctl/record_e2e_fixture.hpp"
#include "tests/support/process.hpp"
#include "tests/support/recordings.hpp"

namespace stereod {
namespace {

using namespace record_e2e;

TEST_F(RecordE2e, RawSnapshotIsTheRecordedPairAsCaptured)
{
    startService(true);
    ProtocolClient client(socket_, 30000ms);
    Json hello = client.request({{"cmd", "hello"}});
    const auto items = hello["snapshot_items"].get<std::vector<std::string>>();
    EXPECT_NE(std::find(items.begin(), items.end(), "raw_left"), items.end());
    EXPECT_NE(std::find(items.begin(), items.end(), "raw_right"), items.end());
    const auto streams = hello["streams"].get<std::vector<std::string>>();
    EXPECT_NE(std::find(streams.begin(), streams.end(), "raw"), streams.end());
    EXPECT_EQ(hello["calibrated"], true);

    // Twice: the first waits for the next pair (raw frames are copied only once asked
    // for), the second is answered from the newest result at once.
    for (int round = 0; round < 2; ++round) {
        Json reply = client.request(
            {{"cmd", "snapshot"}, {"items", Json::array({"raw_left", "raw_right"})}});
        ASSERT_EQ(reply["ok"], true) << reply.dump();
        ASSERT_EQ(reply["payloads"].size(), 2u);
        Json left_descriptor = reply["payloads"][0];
        Json right_descriptor = reply["payloads"][1];
        EXPECT_EQ(left_descriptor["name"], "raw_left");
        EXPECT_EQ(right_descriptor["name"], "raw_right");
        const cv::Mat left = readGray(client, left_descriptor);
        const cv::Mat right = readGray(client, right_descriptor);
        const SourcePair* source = pairWithStamps(left_descriptor.value("stamp_ns", int64_t{0}),
                                                  right_descriptor.value("stamp_ns", int64_t{0}));
        ASSERT_NE(source, nullptr) << reply.dump();
        EXPECT_TRUE(sameImage(left, source->left));
        EXPECT_TRUE(sameImage(right, source->right));
    }
}

TEST_F(RecordE2e, RawStreamCarriesTheRecordedStampsAndPixels)
{
    startService(true);
    ProtocolClient client(socket_, 30000ms);
    Json reply = client.request({{"cmd", "subscribe"}, {"stream", "raw"}});
    ASSERT_EQ(reply["ok"], true) << reply.dump();
    EXPECT_EQ(reply["stream"], "raw");
    std::map<int64_t, int> seen;
    for (int event_count = 0; event_count < 2 * kSourcePairs; ++event_count) {
        Json event = client.readJson();
        ASSERT_EQ(event["event"], "raw") << event.dump();
        ASSERT_EQ(event["payloads"].size(), 2u);
        const int64_t left_stamp = event.value("left_stamp_ns", int64_t{0});
        const int64_t right_stamp = event.value("right_stamp_ns", int64_t{0});
        const cv::Mat left = readGray(client, event["payloads"][0]);
        const cv::Mat right = readGray(client, event["payloads"][1]);
        EXPECT_EQ(event["payloads"][0].value("stamp_ns", int64_t{0}), left_stamp);
        EXPECT_EQ(event["payloads"][1].value("stamp_ns", int64_t{0}), right_stamp);
        const SourcePair* source = pairWithStamps(left_stamp, right_stamp);
        ASSERT_NE(source, nullptr) << event.dump();
        EXPECT_TRUE(sameImage(left, source->left));
        EXPECT_TRUE(sameImage(right, source->right));
        ++seen[left_stamp];
    }
    // Two loops of a six-pair recording: most pairs come by (a busy machine may skip some).
    EXPECT_GE(seen.size(), static_cast<std::size_t>(kSourcePairs / 2));
}

TEST_F(RecordE2e, UncalibratedServiceServesRawFramesAndNoDistance)
{
    startService(false);
    ProtocolClient client(socket_, 30000ms);
    EXPECT_EQ(client.request({{"cmd", "hello"}})["calibrated"], false);

    Json reading = client.request({{"cmd", "distance"}})["reading"];
    EXPECT_EQ(reading["valid"], false);
    EXPECT_EQ(reading["reason"]["code"], "uncalibrated") << reading.dump();

    Json status = client.request({{"cmd", "status"}})["status"];
    EXPECT_EQ(status["state"], "uncalibrated") << status.dump();
    EXPECT_EQ(status["calibration"]["kind"], "none");

    Json calibration = client.request({{"cmd", "calibration"}});
    EXPECT_EQ(calibration["ok"], true);
    EXPECT_EQ(calibration["calibrated"], false);

    Json snapshot = client.request({{"cmd", "snapshot"}, {"items", Json::array({"raw_left"})}});
    ASSERT_EQ(snapshot["ok"], true) << snapshot.dump();
    Json descriptor = snapshot["payloads"][0];
    const cv::Mat left = readGray(client, descriptor);
    bool matched = false;
    for (const SourcePair& pair : source_)
        matched = matched || (pair.left_stamp_ns == descriptor.value("stamp_ns", int64_t{0}) &&
                              sameImage(left, pair.left));
    EXPECT_TRUE(matched) << snapshot.dump();

    // The command line: exit 2 (the service is not producing distances) and the reason.
    const ProcessResult distance = ctl({"distance"});
    EXPECT_EQ(distance.exit_code, 2) << distance.out << distance.err;
    EXPECT_NE(distance.out.find("calibration"), std::string::npos) << distance.out;
}

TEST_F(RecordE2e, RecordingReplaysAsTheSamePairs)
{
    startService(true);
    const std::string out = dir_.file("rec");
    const ProcessResult recorded = ctl({"record", "--out", out, "--frames", "8", "--json"});
    ASSERT_EQ(recorded.exit_code, 0) << recorded.out << recorded.err;
    const Json summary = Json::parse(recorded.out);
    EXPECT_EQ(summary["pairs"], 8);
    EXPECT_EQ(summary["ended"], "frames");
    EXPECT_EQ(summary["calibration"], true);
    EXPECT_NE(recorded.err.find("recording: "), std::string::npos) << recorded.err;

    expectSourcePairs(out, 8);
    // The calibration in force, as its file says it.
    EXPECT_EQ(readFile(out + "/calibration.yaml"), readFile(calibration_));
    EXPECT_NO_THROW(loadCalibration(out + "/calibration.yaml"));

    // Through the replay source, as stereod would play it: the same pairs, in order.
    const Recording recording = openRecording(out, 10.0);
    ReplayOptions options;
    options.path = out;
    options.pacing = ReplayPacing::Lockstep;
    options.loop = false;
    ReplaySource replay(options);
    PairRing ring(4);
    ASSERT_EQ(replay.start(ring), 0) << replay.status().last_error;
    for (const RecordingEntry& entry : recording.entries) {
        std::optional<StereoPair> pair = ring.pop();
        ASSERT_TRUE(pair && pair->left && pair->right);
        EXPECT_EQ(pair->left->source_stamp_ns, entry.left_stamp_ns);
        EXPECT_EQ(pair->right->source_stamp_ns, entry.right_stamp_ns);
        const SourcePair* source = pairWithStamps(entry.left_stamp_ns, entry.right_stamp_ns);
        ASSERT_NE(source, nullptr);
        EXPECT_TRUE(sameImage(pair->left->image, source->left));
        EXPECT_TRUE(sameImage(pair->right->image, source->right));
    }
    replay.stop();

    // Never over a user's data.
    const ProcessResult again = ctl({"record", "--out", out, "--frames", "1"});
    EXPECT_EQ(again.exit_code, 2) << again.out << again.err;
    EXPECT_NE(again.err.find("not empty"), std::string::npos) << again.err;
}

TEST_F(RecordE2e, KilledRecorderLeavesARecordingThatReplays)
{
    startService(true);
    const std::string out = dir_.file("killed");
    ChildProcess recorder({stereoctlPath(), "record", "--out", out, "--socket", socket_},
                          dir_.file("record.log"));
    // Until a few rows are there, then kill -9 in the middle of whatever it does.
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    std::size_t rows = 0;
    while (std::chrono::steady_clock::now() < deadline && rows < 4) {
        const std::string csv = readFile(out + "/frames.csv");
        rows = static_cast<std::size_t>(std::count(csv.begin(), csv.end(), '\n'));
        rows = rows > 0 ? rows - 1 : 0;
        std::this_thread::sleep_for(5ms);
    }
    ASSERT_GE(rows, 4u) << readFile(dir_.file("record.log"));
    recorder.sendSignal(SIGKILL);
    ASSERT_TRUE(recorder.waitFor(10s));

    // Every row's images are complete; at most the pair in flight has no row.
    expectSourcePairs(out, 4);
    const Recording recording = openRecording(out, 10.0);
    std::size_t left_files = 0;
    for (const auto& file : fs::directory_iterator(out + "/left"))
        left_files += file.path().extension() == ".png" ? 1 : 0;
    EXPECT_LE(left_files, recording.entries.size() + 1);
}

TEST_F(RecordE2e, McapRecordingHoldsThePairsAndTheCalibration)
{
    startService(true);
    const std::string out = dir_.file("rec.mcap");
    const ProcessResult recorded = ctl({"record", "--out", out, "--frames", "8", "--json"});
    ASSERT_EQ(recorded.exit_code, 0) << recorded.out << recorded.err;
    const Json summary = Json::parse(recorded.out);
    EXPECT_EQ(summary["pairs"], 8);
    EXPECT_EQ(summary["calibration"], true);
    EXPECT_EQ(expectBagOfSourcePairs(out, source_), 8u);

    mcap::Reader reader(out);
    EXPECT_TRUE(reader.hasSummary());
    EXPECT_EQ(reader.header().profile, "ros2");
    const McapStereoIndex index = indexMcapStereo(reader, "", "");
    ASSERT_TRUE(index.camera_info.has_value());
    // The calibration in force, through ROS's convention (right P[3] = -fx' * B).
    EXPECT_NEAR(index.camera_info->second.p[3], -kFocalPx * kBaselineM, 1e-9);
    const StereoCalibration back = calibrationFromRosCameraInfo(
        rosCameraInfoFromMessage(index.camera_info->first),
        rosCameraInfoFromMessage(index.camera_info->second), "left", "right");
    EXPECT_NEAR(back.rectified.focal_px, kFocalPx, 1e-9);
    EXPECT_NEAR(back.rectified.baseline_m, kBaselineM, 1e-12);

    // And @mcap/core reads it, rosmsg2-serialization decoding the first image and
    // camera_info of each side: the source pair's pixels, the calibration in force.
    const std::string interop = interopScripts();
    if (!interop.empty()) {
        const ProcessResult node = runProcess({STEREOD_NODE, interop + "/read_ours.mjs", out});
        ASSERT_EQ(node.exit_code, 0) << node.err;
        const Json got = Json::parse(node.out);
        EXPECT_EQ(got["profile"], "ros2");
        EXPECT_EQ(got["messageCount"], 32);
        EXPECT_EQ(got["streamDone"], true);
        for (const Json& channel : got["channels"]) {
            EXPECT_EQ(channel["count"], 8) << channel.dump();
            EXPECT_EQ(channel["schemaEncoding"], "ros2msg") << channel.dump();
            EXPECT_EQ(channel["messageEncoding"], "cdr") << channel.dump();
        }
        const Json& left = got["first"][kMcapLeftImageTopic];
        const Json& right = got["first"][kMcapRightImageTopic];
        EXPECT_EQ(left["message"]["width"], kSize.width);
        EXPECT_EQ(left["message"]["encoding"], "mono8");
        const SourcePair* source = nullptr;
        for (const SourcePair& pair : source_)
            if (left["message"]["data"] == test::base64(pair.left))
                source = &pair;
        ASSERT_NE(source, nullptr) << "the bag's first left image is no source pair's";
        EXPECT_EQ(right["message"]["data"], test::base64(source->right));
        const Json& left_info = got["first"][kMcapLeftInfoTopic]["message"];
        const Json& right_info = got["first"][kMcapRightInfoTopic]["message"];
        EXPECT_DOUBLE_EQ(left_info["k"][0].get<double>(), kFocalPx);
        EXPECT_DOUBLE_EQ(right_info["p"][0].get<double>(), kFocalPx);
        EXPECT_NEAR(right_info["p"][3].get<double>(), -kFocalPx * kBaselineM, 1e-9);
        EXPECT_EQ(left_info["width"], kSize.width);
        EXPECT_EQ(left_info["height"], kSize.height);
    }

    // Never over a user's file.
    const ProcessResult again = ctl({"record", "--out", out, "--frames", "1"});
    EXPECT_EQ(again.exit_code, 2) << again.out << again.err;
    EXPECT_NE(again.err.find("exists"), std::string::npos) << again.err;
}

// One time base: a bag recorded from a replay that loops (6 pairs, 14 recorded) carries
// the wall clock of each pair's delivery, so its log times never step back, and replaying
// it gives no warning about stamps that do; the readings carry the same time base beside
// their CLOCK_MONOTONIC stamp.
TEST_F(RecordE2e, ALoopingReplayRecordsStampsThatNeverStepBack)
{
    startService(true);
    const std::string out = dir_.file("loop.mcap");
    const ProcessResult recorded = ctl({"record", "--out", out, "--frames", "14", "--json"});
    ASSERT_EQ(recorded.exit_code, 0) << recorded.out << recorded.err;
    const Json summary = Json::parse(recorded.out);
    EXPECT_EQ(summary["file"], out);
    EXPECT_FALSE(summary.contains("dir"));
    EXPECT_EQ(expectBagOfSourcePairs(out, source_), 14u);

    // Every message, in file order: log time = header stamp, never stepping back per topic.
    mcap::Reader reader(out);
    std::map<std::string, uint64_t> last;
    std::size_t messages = 0;
    reader.forEachMessage([&](const mcap::MessageView& message, const mcap::MessageRef&) {
        const std::string& topic = reader.channels().at(message.channel_id).topic;
        const int64_t stamp = topic.find("camera_info") == std::string::npos
                                  ? ros2::parseImage(message.data).header.stamp.toNs()
                                  : ros2::parseCameraInfo(message.data).header.stamp.toNs();
        EXPECT_EQ(message.log_time_ns, static_cast<uint64_t>(stamp)) << topic;
        EXPECT_GE(message.log_time_ns, last[topic]) << topic << ": the log time steps back";
        last[topic] = message.log_time_ns;
        ++messages;
    });
    EXPECT_EQ(messages, 4u * 14u);

    const Replayed replayed = replayOnce(out, "replay");
    EXPECT_EQ(replayed.reading.value("valid", false), true)
        << replayed.reading.dump() << replayed.log;
    EXPECT_EQ(replayed.log.find("step back"), std::string::npos) << replayed.log;

    // The reading: stamp_ns on CLOCK_MONOTONIC, stamp_realtime_ns the same instant on the
    // wall clock.
    timespec mono{}, real{};
    clock_gettime(CLOCK_MONOTONIC, &mono);
    clock_gettime(CLOCK_REALTIME, &real);
    const int64_t offset_ns =
        (real.tv_sec - mono.tv_sec) * 1'000'000'000LL + (real.tv_nsec - mono.tv_nsec);
    ProtocolClient client(socket_, 10000ms);
    const Json now = client.request({{"cmd", "distance"}})["reading"];
    ASSERT_TRUE(now.contains("stamp_realtime_ns")) << now.dump();
    EXPECT_NEAR(static_cast<double>(now["stamp_realtime_ns"].get<int64_t>() -
                                    now["stamp_ns"].get<int64_t>()),
                static_cast<double>(offset_ns), 5e6);
}

TEST_F(RecordE2e, KilledMcapRecorderLeavesABagThatReplays)
{
    startService(true);
    const std::string out = dir_.file("killed.mcap");
    ChildProcess recorder({stereoctlPath(), "record", "--out", out, "--socket", socket_},
                          dir_.file("record.log"));
    // Until two chunks (4 MiB each, about 19 pairs of 384x288) are on disk, then kill -9
    // in the middle of whatever it does.
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    std::error_code error;
    while (std::chrono::steady_clock::now() < deadline &&
           (!fs::exists(out) || fs::file_size(out, error) < 9u << 20))
        std::this_thread::sleep_for(10ms);
    ASSERT_GE(fs::file_size(out, error), 9u << 20) << readFile(dir_.file("record.log"));
    recorder.sendSignal(SIGKILL);
    ASSERT_TRUE(recorder.waitFor(10s));

    mcap::Reader reader(out);
    EXPECT_FALSE(reader.hasSummary());
    EXPECT_GE(reader.chunks().size(), 2u);
    EXPECT_GE(expectBagOfSourcePairs(out, source_), 30u);

    // stereod replays it, with the calibration its camera_info carries.
    const Replayed replayed = replayOnce(out, "replay");
    EXPECT_EQ(replayed.reading.value("valid", false), true)
        << replayed.reading.dump() << replayed.log;
    EXPECT_NE(replayed.log.find("calibration from"), std::string::npos) << replayed.log;
}

// A bag as a robot's recorder writes it (@mcap/core's writer and rosmsg2-serialization:
// its own topic names, an unrelated third image topic, camera_info beside the images)
// replays through stereod and gives the distance the CSV recording of the same pairs gives.
TEST_F(RecordE2e, BagFromAnIndependentWriterGivesTheDistanceOfTheCsvRecording)
{
    const std::string interop = interopScripts();
    if (interop.empty())
        GTEST_SKIP() << "node is not installed";
    ASSERT_FALSE(HasFailure());
    startService(true);
    const Json csv_reading = firstReading(socket_, *service_, log_);
    ASSERT_EQ(csv_reading.value("valid", false), true) << csv_reading.dump();

    const auto [left_info, right_info] = rosCameraInfoPair(loadCalibration(calibration_));
    auto info_json = [](const RosCameraInfo& i) {
        const ros2::CameraInfo m = cameraInfoMessage(i);
        return Json{
            {"width", m.width}, {"height", m.height}, {"distortion_model", m.distortion_model},
            {"d", m.d},         {"k", m.k},           {"r", m.r},
            {"p", m.p}};
    };
    Json spec = {
        {"left_topic", "/rig/cam_left/image_mono"}, {"right_topic", "/rig/cam_right/image_mono"},
        {"other_topic", "/rig/front/image_color"},  {"left_info", info_json(left_info)},
        {"right_info", info_json(right_info)},      {"pairs", Json::array()}};
    for (std::size_t k = 0; k < source_.size(); ++k) {
        const std::string l = dir_.file("l" + std::to_string(k) + ".pgm");
        const std::string r = dir_.file("r" + std::to_string(k) + ".pgm");
        ASSERT_TRUE(cv::imwrite(l, source_[k].left));
        ASSERT_TRUE(cv::imwrite(r, source_[k].right));
        spec["pairs"].push_back({{"left", l},
                                 {"right", r},
                                 {"left_stamp_ns", source_[k].left_stamp_ns},
                                 {"right_stamp_ns", source_[k].right_stamp_ns}});
    }
    std::ofstream(dir_.file("spec.json")) << spec.dump();
    const std::string bag = dir_.file("robot.mcap");
    const ProcessResult wrote =
        runProcess({STEREOD_NODE, interop + "/write_bag.mjs", bag, dir_.file("spec.json")});
    ASSERT_EQ(wrote.exit_code, 0) << wrote.err;

    // No --calib: the calibration comes from the bag's camera_info.
    const std::string log = dir_.file("bag.log");
    const std::string socket = dir_.file("b.sock");
    ChildProcess replay({stereodPath(), "--replay", bag, "--socket", socket}, log);
    const Json bag_reading = firstReading(socket, replay, log);
    ASSERT_EQ(bag_reading.value("valid", false), true) << bag_reading.dump() << readFile(log);
    EXPECT_NE(readFile(log).find("image topics chosen by name"), std::string::npos)
        << readFile(log);
    // The pairs differ only in brightness: any two readings agree within 1 %.
    const double csv_m = csv_reading["distance_m"].get<double>();
    const double bag_m = bag_reading["distance_m"].get<double>();
    EXPECT_NEAR(bag_m, csv_m, csv_m * 0.01) << bag_reading.dump() << "\n" << csv_reading.dump();
    replay.sendSignal(SIGTERM);
    replay.waitFor(10s);
}

TEST_F(RecordE2e, FullDiskStopsTheRecordingAndNotTheService)
{
    startService(true);
    const std::string out = dir_.file("full");
    // Room for the header, the calibration and a few pairs (each about 2 x 90 kB of PNG).
    const ProcessResult recorded =
        ctl({"record", "--out", out, "--json"},
            {"LD_PRELOAD=" STEREOD_DISK_FULL_PRELOAD, "STEREOD_TEST_FULL_DIR=" + out,
             "STEREOD_TEST_FULL_BYTES=600000", "ASAN_OPTIONS=verify_asan_link_order=0"});
    ASSERT_EQ(recorded.exit_code, 2) << recorded.out << recorded.err;
    EXPECT_NE(recorded.err.find("No space left on device"), std::string::npos) << recorded.err;
    EXPECT_NE(recorded.err.find(out + "/"), std::string::npos) << recorded.err;
    const Json summary = Json::parse(recorded.out);
    EXPECT_EQ(summary["ended"], "write_failed");

    // What was written before the disk filled up is a recording.
    expectSourcePairs(out, 1);

    // The service never noticed.
    ProtocolClient client(socket_, 30000ms);
    Json reading = client.request({{"cmd", "distance"}})["reading"];
    EXPECT_EQ(reading["valid"], true) << reading.dump();
    EXPECT_TRUE(service_->running());
}

// Issue 23: a bag that reached the file size limit (ulimit -f) killed stereoctl with
// SIGXFSZ (exit 153, no word), and a bag on a full disk was reported with the pairs of the
// chunk the disk refused (303 said, 285 replayed). The recorder now stops with the reason,
// and the count is what a replay finds.
TEST_F(RecordE2e, ABagAtTheFileSizeLimitOrOnAFullDiskCountsWhatReplays)
{
    startService(true);
    // About 2.5 MB a chunk of 4 MiB: the first chunk fits, the second does not.
    const std::string limited = dir_.file("limited.mcap");
    const ProcessResult at_limit =
        runProcess({"/usr/bin/prlimit", "--fsize=4000000", "--", stereoctlPath(), "record", "--out",
                    limited, "--frames", "100", "--json", "--socket", socket_});
    EXPECT_EQ(at_limit.signal, 0) << at_limit.err;
    ASSERT_EQ(at_limit.exit_code, 2) << at_limit.out << at_limit.err;
    EXPECT_NE(at_limit.err.find("File too large"), std::string::npos) << at_limit.err;
    const Json limited_summary = Json::parse(at_limit.out);
    EXPECT_EQ(limited_summary["ended"], "write_failed");
    const std::size_t limited_pairs = expectBagOfSourcePairs(limited, source_);
    EXPECT_GT(limited_pairs, 0u);
    EXPECT_EQ(limited_summary["pairs"].get<std::size_t>(), limited_pairs) << at_limit.out;

    const std::string full = dir_.file("full/run.mcap");
    fs::create_directory(dir_.file("full"));
    const ProcessResult on_full =
        ctl({"record", "--out", full, "--frames", "100", "--json"},
            {"LD_PRELOAD=" STEREOD_DISK_FULL_PRELOAD, "STEREOD_TEST_FULL_DIR=" + dir_.file("full"),
             "STEREOD_TEST_FULL_BYTES=4000000", "ASAN_OPTIONS=verify_asan_link_order=0"});
    ASSERT_EQ(on_full.exit_code, 2) << on_full.out << on_full.err;
    const Json full_summary = Json::parse(on_full.out);
    const std::size_t full_pairs = expectBagOfSourcePairs(full, source_);
    EXPECT_GT(full_pairs, 0u);
    EXPECT_EQ(full_summary["pairs"].get<std::size_t>(), full_pairs) << on_full.out;
}

} // namespace
} // namespace stereod
