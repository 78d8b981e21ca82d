// Our MCAP files against independent implementations (tests/mcap_interop, Node.js):
//  - a bag we write is read by @mcap/core (through its summary, and record by record with
//    every CRC checked), and its Image and CameraInfo decoded by
//    @foxglove/rosmsg2-serialization match the pixels and the calibration we wrote;
//  - a bag written by @mcap/core's writer with rosmsg2-serialization (topics of its own
//    naming, an unrelated third image topic, right images before left ones) is read and
//    paired by ours;
//  - a bag cut mid-way (a recorder killed) is read by both up to its last complete chunk.
//
// The Node packages are installed by scripts/setup-node.sh (called by scripts/test.sh);
// without node the tests skip, without the packages they fail and say what to run.

#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/calibration_formats.hpp"
#include "replay/mcap_recording.hpp"
#include "tests/support/process.hpp"
#include "tests/support/recordings.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using json = nlohmann::json;

const std::string kInteropDir = std::string(STEREOD_SOURCE_DIR) + "/tests/mcap_interop";

class McapInterop : public ::testing::Test {
  protected:
    void SetUp() override
    {
        if (std::string(STEREOD_NODE).empty()) {
            GTEST_SKIP() << "node is not installed";
        }
        std::ifstream probe(kInteropDir + "/node_modules/@mcap/core/package.json");
        ASSERT_TRUE(probe.good()) << "the interop packages are missing: run scripts/setup-node.sh";
    }

    // Runs one of the scripts and returns the JSON object it prints.
    json node(const std::vector<std::string>& args)
    {
        std::vector<std::string> argv = {STEREOD_NODE};
        argv.insert(argv.end(), args.begin(), args.end());
        const test::ProcessResult r = test::runProcess(argv);
        EXPECT_EQ(r.exit_code, 0) << r.err;
        try {
            return json::parse(r.out);
        } catch (const json::exception& e) {
            ADD_FAILURE() << "node printed no JSON: " << e.what() << "\n" << r.out << r.err;
            return json::object();
        }
    }

    test::TempDir dir_;
};

// A rectified calibration (the Middlebury Tsukuba geometry) as a ROS camera_info pair.
std::pair<ros2::CameraInfo, ros2::CameraInfo> cameraInfoPair(cv::Size size)
{
    const StereoCalibration calibration =
        makeRectifiedCalibration(size, 615.0, 0.10, size.width / 2.0 - 0.5, size.height / 2.0);
    const auto [l, r] = rosCameraInfoPair(calibration);
    return {cameraInfoMessage(l), cameraInfoMessage(r)};
}

TEST_F(McapInterop, OurBagReadByMcapCoreAndRosmsg2Serialization)
{
    const cv::Size size(96, 72);
    auto pairs = test::tsukubaPairs(5, size);
    test::stampPairs(pairs, 5'000'000'000, 100'000'000);
    const auto [left_info, right_info] = cameraInfoPair(size);
    const std::string path = dir_.file("ours.mcap");
    {
        McapRecordingWriter writer(path);
        writer.setCameraInfo(left_info, right_info);
        for (const auto& p : pairs) {
            writer.write(p.left, p.right, p.left_stamp_ns, p.right_stamp_ns);
        }
        writer.close();
    }
    const json got = node({kInteropDir + "/read_ours.mjs", path});
    EXPECT_EQ(got["profile"], "ros2");
    EXPECT_EQ(got["library"], "stereod");
    EXPECT_EQ(got["compression"], json::array({"zstd"}));
    EXPECT_EQ(got["messageCount"], 20);
    EXPECT_EQ(got["ordered"], true);
    EXPECT_EQ(got["streamDone"], true) << "the streaming reader did not reach the footer";
    EXPECT_EQ(got["streamed"]["Message"], 20);
    EXPECT_EQ(got["streamed"]["DataEnd"], 1);
    EXPECT_EQ(got["streamed"]["Footer"], 1);
    ASSERT_EQ(got["channels"].size(), 4u);
    for (const json& c : got["channels"]) {
        const std::string topic = c["topic"];
        EXPECT_EQ(c["messageEncoding"], "cdr") << topic;
        EXPECT_EQ(c["schemaEncoding"], "ros2msg") << topic;
        EXPECT_EQ(c["qos"], true) << topic;
        EXPECT_EQ(c["count"], 5) << topic;
        EXPECT_EQ(got["counted"][topic], 5) << topic;
        EXPECT_EQ(c["schemaName"], topic.find("image_raw") != std::string::npos
                                       ? "sensor_msgs/msg/Image"
                                       : "sensor_msgs/msg/CameraInfo")
            << topic;
    }

    const json& left = got["first"][kMcapLeftImageTopic];
    EXPECT_EQ(left["logTime"], pairs[0].left_stamp_ns);
    EXPECT_EQ(left["message"]["header"]["stamp"]["sec"], pairs[0].left_stamp_ns / 1'000'000'000);
    EXPECT_EQ(left["message"]["header"]["stamp"]["nanosec"],
              pairs[0].left_stamp_ns % 1'000'000'000);
    EXPECT_EQ(left["message"]["header"]["frame_id"], "stereo_left_optical_frame");
    EXPECT_EQ(left["message"]["encoding"], "mono8");
    EXPECT_EQ(left["message"]["width"], size.width);
    EXPECT_EQ(left["message"]["height"], size.height);
    EXPECT_EQ(left["message"]["step"], size.width);
    EXPECT_EQ(left["message"]["data"], test::base64(pairs[0].left));
    const json& right = got["first"][kMcapRightImageTopic];
    EXPECT_EQ(right["logTime"], pairs[0].right_stamp_ns);
    EXPECT_EQ(right["message"]["data"], test::base64(pairs[0].right));

    const json& info = got["first"][kMcapRightInfoTopic]["message"];
    EXPECT_EQ(info["distortion_model"], "plumb_bob");
    EXPECT_EQ(info["width"], size.width);
    for (int i = 0; i < 9; ++i) {
        EXPECT_DOUBLE_EQ(info["k"][i].get<double>(), right_info.k[i]) << i;
    }
    for (int i = 0; i < 12; ++i) {
        EXPECT_DOUBLE_EQ(info["p"][i].get<double>(), right_info.p[i]) << i;
    }
    // ROS's convention for the right camera: P[3] = Tx = -fx' * baseline.
    EXPECT_NEAR(info["p"][3].get<double>(), -615.0 * 0.10, 1e-9);
    EXPECT_EQ(got["first"][kMcapLeftInfoTopic]["message"]["p"][3], 0.0);
}

TEST_F(McapInterop, BagWrittenByMcapCoreIsPairedByOurReader)
{
    const cv::Size size(96, 72);
    auto pairs = test::tsukubaPairs(6, size);
    test::stampPairs(pairs, 7'000'000'000, 66'666'667);
    const auto [left_info, right_info] = cameraInfoPair(size);
    auto info_json = [](const ros2::CameraInfo& i) {
        return json{
            {"width", i.width}, {"height", i.height}, {"distortion_model", i.distortion_model},
            {"d", i.d},         {"k", i.k},           {"r", i.r},
            {"p", i.p}};
    };
    json spec = {
        {"left_topic", "/robot/cam_left/image"},     {"right_topic", "/robot/cam_right/image"},
        {"other_topic", "/robot/front/image_color"}, {"left_info", info_json(left_info)},
        {"right_info", info_json(right_info)},       {"pairs", json::array()}};
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        const std::string l = dir_.file("l" + std::to_string(k) + ".pgm");
        const std::string r = dir_.file("r" + std::to_string(k) + ".pgm");
        ASSERT_TRUE(cv::imwrite(l, pairs[k].left));
        ASSERT_TRUE(cv::imwrite(r, pairs[k].right));
        spec["pairs"].push_back({{"left", l},
                                 {"right", r},
                                 {"left_stamp_ns", pairs[k].left_stamp_ns},
                                 {"right_stamp_ns", pairs[k].right_stamp_ns}});
    }
    std::ofstream(dir_.file("spec.json")) << spec.dump();
    const std::string path = dir_.file("theirs.mcap");
    EXPECT_EQ(node({kInteropDir + "/write_bag.mjs", path, dir_.file("spec.json")})["pairs"], 6);

    mcap::Reader reader(path);
    EXPECT_TRUE(reader.hasSummary());
    EXPECT_EQ(reader.header().profile, "ros2");
    const McapStereoIndex index = indexMcapStereo(reader, "", "");
    EXPECT_EQ(index.left_topic, "/robot/cam_left/image");
    EXPECT_EQ(index.right_topic, "/robot/cam_right/image");
    ASSERT_EQ(index.pairs.size(), pairs.size());
    EXPECT_EQ(index.unpaired_left, 0u);
    EXPECT_EQ(index.unpaired_right, 0u);
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        EXPECT_EQ(index.pairs[k].left_stamp_ns, pairs[k].left_stamp_ns);
        EXPECT_EQ(index.pairs[k].right_stamp_ns, pairs[k].right_stamp_ns);
        cv::Mat l, r;
        std::string why;
        ASSERT_TRUE(decodeMcapImage(reader, index.pairs[k].left, l, why)) << why;
        ASSERT_TRUE(decodeMcapImage(reader, index.pairs[k].right, r, why)) << why;
        EXPECT_TRUE(test::samePixels(l, pairs[k].left)) << k;
        EXPECT_TRUE(test::samePixels(r, pairs[k].right)) << k;
    }
    ASSERT_TRUE(index.camera_info.has_value());
    EXPECT_EQ(index.camera_info->second.p, right_info.p);
    EXPECT_EQ(index.camera_info->first.k, left_info.k);

    // Named topics too, and a wrong name is refused with the bag's image topics listed.
    EXPECT_EQ(
        indexMcapStereo(reader, "/robot/cam_left/image", "/robot/cam_right/image").pairs.size(),
        6u);
    try {
        indexMcapStereo(reader, "/stereo/left/image_raw", "/robot/cam_right/image");
        FAIL() << "a missing topic was accepted";
    } catch (const mcap::McapError& e) {
        EXPECT_NE(std::string(e.what()).find("/robot/front/image_color"), std::string::npos)
            << e.what();
    }
}

TEST_F(McapInterop, CutBagReadableUpToItsLastCompleteChunk)
{
    const cv::Size size(96, 72);
    auto pairs = test::tsukubaPairs(16, size);
    test::stampPairs(pairs, 1'000'000'000, 100'000'000);
    const auto [left_info, right_info] = cameraInfoPair(size);
    const std::string path = dir_.file("full.mcap");
    mcap::WriterOptions options = McapRecordingWriter::defaultOptions();
    options.chunk_size_bytes = 40'000; // about 2 pairs a chunk
    {
        McapRecordingWriter writer(path, options);
        writer.setCameraInfo(left_info, right_info);
        for (int loop = 0; loop < 3; ++loop) {
            for (auto& p : pairs) {
                writer.write(p.left, p.right, p.left_stamp_ns, p.right_stamp_ns);
                p.left_stamp_ns += 1'600'000'000;
                p.right_stamp_ns += 1'600'000'000;
            }
        }
        writer.close();
    }
    std::ifstream in(path, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), {});
    // A kill -9 in the middle of writing a chunk: the file ends inside it.
    const std::string cut = dir_.file("cut.mcap");
    std::ofstream(cut, std::ios::binary)
        .write(bytes.data(), static_cast<std::streamsize>(bytes.size() * 6 / 10));

    mcap::Reader reader(cut);
    EXPECT_FALSE(reader.hasSummary());
    EXPECT_TRUE(reader.truncated());
    const McapStereoIndex index = indexMcapStereo(reader, "", "");
    // 48 pairs in about 24 chunks: 60 % of the file keeps all but at most one chunk's
    // worth of the pairs before the cut.
    EXPECT_GE(index.pairs.size(), 48u * 6 / 10 - 3);
    EXPECT_LE(index.pairs.size(), 48u * 6 / 10);
    EXPECT_TRUE(index.camera_info.has_value());

    const json got = node({kInteropDir + "/read_truncated.mjs", cut});
    EXPECT_EQ(got["done"], false);
    EXPECT_TRUE(got["error"].is_null()) << got.dump();
    EXPECT_EQ(got["counts"][kMcapLeftImageTopic], index.pairs.size());
    EXPECT_EQ(got["counts"][kMcapRightImageTopic], index.pairs.size());
}

} // namespace
} // namespace stereod
