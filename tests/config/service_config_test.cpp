// The service configuration: the examples load, every rejected value is named with its
// key and file:line, all problems come at once, paths resolve against the file.

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include "config/service_config.hpp"
#include "pipeline/census_sgm_matcher.hpp"
#include "pipeline/matcher_defaults.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

namespace fs = std::filesystem;

std::string readText(const fs::path& path)
{
    std::ifstream in(path);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
}

// 1-based line of the first line of `text` that contains `fragment`; 0 if none.
int lineOf(const std::string& text, const std::string& fragment)
{
    std::istringstream in(text);
    std::string line;
    for (int number = 1; std::getline(in, line); ++number) {
        if (line.find(fragment) != std::string::npos) {
            return number;
        }
    }
    return 0;
}

// The problems parseConfig() reports for `yaml`; empty when it accepts the text.
std::vector<std::string> problemsOf(const std::string& yaml, const std::string& origin = "t.yaml")
{
    try {
        parseConfig(yaml, origin);
    } catch (const ConfigError& error) {
        return error.problems();
    }
    return {};
}

std::string joined(const std::vector<std::string>& problems)
{
    std::string out;
    for (const auto& problem : problems) {
        out += problem + "\n";
    }
    return out;
}

TEST(ConfigDefaults, ValidateAndSuitARobot)
{
    const ServiceConfig config = defaultConfig();
    EXPECT_NO_THROW(validateConfig(config));
    EXPECT_EQ(config.origin, "<defaults>");
    EXPECT_EQ(config.source.kind, SourceKind::Replay);
    EXPECT_EQ(config.source.replay.pacing, ReplayPacing::Paced);
    EXPECT_TRUE(config.source.replay.loop);
    // A replay keeps the colour a camera would keep by default.
    EXPECT_EQ(config.source.replay.colour, config.source.cameras.colour);
    EXPECT_EQ(config.socket.path, "/run/stereod/stereod.sock");
    EXPECT_EQ(config.socket.mode, 0660u);
    EXPECT_EQ(config.log_level, "info");
    EXPECT_TRUE(config.processing.compute_cloud);
}

TEST(ConfigDefaults, EmptyOrCommentOnlyTextGivesTheDefaults)
{
    for (const std::string text : {"", "\n\n", "# nothing here\n", "---\n"}) {
        const ServiceConfig config = parseConfig(text, "empty.yaml");
        EXPECT_EQ(config.origin, "empty.yaml");
        const ConfigChange change = diffConfig(defaultConfig(), config);
        EXPECT_TRUE(change.changed.empty()) << "text: " << text;
    }
}

TEST(ConfigDefaults, KeysNotGivenKeepTheirDefaults)
{
    const ServiceConfig config = parseConfig("nearest:\n  max_depth_m: 3\n", "t.yaml");
    EXPECT_DOUBLE_EQ(config.processing.nearest.max_depth_m, 3.0);
    const ConfigChange change = diffConfig(defaultConfig(), config);
    EXPECT_EQ(change.changed, std::vector<std::string>{"nearest.max_depth_m"});
}

// A key the table marks live must reach the running service: a live key with no part
// would be reported changed on reload and applied nowhere.
TEST(ConfigLiveParts, EveryLiveKeyReachesAPartAndNoOtherKeyDoes)
{
    std::size_t live = 0;
    for (const auto& key : configKeys()) {
        EXPECT_EQ(livePartOf(key.path).has_value(), key.live) << key.path;
        live += key.live ? 1 : 0;
    }
    EXPECT_GT(live, 40u);
    EXPECT_EQ(livePartOf("matcher.num_disparities"), LivePart::Processing);
    EXPECT_EQ(livePartOf("point_cloud"), LivePart::Processing);
    EXPECT_EQ(livePartOf("robot.camera_pose.rpy_deg"), LivePart::Zones);
    EXPECT_EQ(livePartOf("zones"), LivePart::Zones);
    EXPECT_EQ(livePartOf("log_level"), LivePart::LogLevel);
    EXPECT_FALSE(livePartOf("source.type").has_value());
    EXPECT_FALSE(livePartOf("no.such.key").has_value());
}

TEST(ConfigLiveParts, AReloadNamesEachChangedPartOnceAndNoneForRestartKeys)
{
    const ServiceConfig config = parseConfig("nearest:\n  max_depth_m: 3\n  min_depth_m: 0.3\n"
                                             "publish:\n  depth_max_hz: 5\n"
                                             "socket:\n  path: /tmp/other.sock\n",
                                             "t.yaml");
    const ConfigChange change = diffConfig(defaultConfig(), config);
    EXPECT_EQ(change.live_parts, (std::vector<LivePart>{LivePart::Processing, LivePart::Publish}));
    EXPECT_EQ(change.restart_needed, std::vector<std::string>{"socket.path"});
}

TEST(ConfigExamples, ReferenceHoldsEveryKeyAtItsDefault)
{
    const fs::path file = fs::path(STEREOD_SOURCE_DIR) / "config/examples/stereod.yaml";
    const ServiceConfig config = loadConfig(file.string());
    EXPECT_TRUE(diffConfig(defaultConfig(), config).changed.empty());

    // Every key of the format is written out, so the reference documents all of them.
    const YAML::Node root = YAML::LoadFile(file.string());
    for (const auto& key : configKeys()) {
        YAML::Node node = root;
        std::stringstream parts(key.path);
        std::string part;
        while (std::getline(parts, part, '.')) {
            node.reset(node[part]);
        }
        EXPECT_TRUE(node.IsDefined()) << key.path << " is missing from " << file;
    }
}

// The Aloe demo, checked where the demo runs it: a recording at build/demo/aloe with its
// calibration.yaml, reached by the config's relative path.
TEST(ConfigExamples, AloeDemoLoadsAgainstItsRecording)
{
    const std::string text =
        readText(fs::path(STEREOD_SOURCE_DIR) / "config/examples/aloe-demo.yaml");
    test::TempDir tree;
    const fs::path file = tree.write("config/examples/aloe-demo.yaml", text);
    const fs::path recording = fs::path(tree.path()) / "build/demo/aloe";
    tree.write("build/demo/aloe/calibration.yaml", "focal_px: 3740\n");

    const ServiceConfig config = loadConfig(file.string());
    EXPECT_EQ(config.source.replay.path, recording.string());
    EXPECT_EQ(config.socket.path, (fs::path(tree.path()) / "build/demo/stereod.sock").string());
    EXPECT_TRUE(config.calibration_path.empty());
    EXPECT_EQ(config.processing.matcher.kind, MatcherKind::CensusSgm);
    EXPECT_DOUBLE_EQ(config.processing.matcher.min_depth_m, 1.2);
    EXPECT_DOUBLE_EQ(config.processing.nearest.max_depth_m, 3.0);
    const RegionOfInterest& roi = config.processing.nearest.roi;
    EXPECT_DOUBLE_EQ(roi.x + roi.width / 2, 0.5);
    EXPECT_DOUBLE_EQ(roi.y + roi.height / 2, 0.5);

    // Aloe's geometry (Middlebury 2006, full size): the scene's 1.2 m must be in sight
    // without hitting the disparity cap.
    RectifiedGeometry aloe;
    aloe.image_size = ImageSize{1282, 1110};
    aloe.focal_px = 3740.0;
    aloe.baseline_m = 0.160;
    aloe.doffs_px = 270.0;
    const DisparityRange range = chooseDisparityRange(config.processing.matcher, aloe);
    EXPECT_FALSE(range.capped);
    EXPECT_EQ(range.num_disparities % 16, 0);
    EXPECT_GE(range.min_disparity + range.num_disparities, aloe.disparityAtDepth(1.2));
    EXPECT_LE(range.closest_depth_m, 1.2);
}

TEST(ConfigExamples, AloeDemoWithoutItsRecordingNamesThePathAndLine)
{
    const std::string text =
        readText(fs::path(STEREOD_SOURCE_DIR) / "config/examples/aloe-demo.yaml");
    test::TempDir tree;
    const fs::path file = tree.write("config/examples/aloe-demo.yaml", text);
    try {
        loadConfig(file.string());
        FAIL() << "a missing recording was accepted";
    } catch (const ConfigError& error) {
        ASSERT_EQ(error.problems().size(), 1u) << error.what();
        const std::string expected = file.string() + ":" +
                                     std::to_string(lineOf(text, "path: ../../build/demo/aloe")) +
                                     ": source.replay.path: does not exist (got " +
                                     (fs::path(tree.path()) / "build/demo/aloe").string();
        EXPECT_EQ(error.problems()[0].rfind(expected, 0), 0u) << error.problems()[0];
        // The exit code's choice reads the keys, not the words.
        EXPECT_TRUE(error.onlyAbout("source.replay.path"));
        EXPECT_FALSE(error.onlyAbout("calibration"));
    }
}

// A problem whose text merely mentions a key is not about it: only the key it names is.
TEST(ConfigError, TellsWhatItIsAboutByItsKeysNotItsWords)
{
    try {
        parseConfig("log_level: \": source.replay.path: \"\n", "words.yaml");
        FAIL() << "a bad log level was accepted";
    } catch (const ConfigError& error) {
        ASSERT_EQ(error.problems().size(), 1u) << error.what();
        EXPECT_NE(error.problems()[0].find(": source.replay.path: "), std::string::npos)
            << error.problems()[0];
        EXPECT_FALSE(error.onlyAbout("source.replay.path"));
        EXPECT_TRUE(error.onlyAbout("log_level"));
    }
    const ConfigError unreadable({std::string("x.yaml: cannot read the configuration")});
    EXPECT_FALSE(unreadable.onlyAbout("source.replay.path"));
}

struct RejectedCase {
    std::string yaml;
    std::string key;
    int line;
    std::string fragment; // a piece of the problem's text
};

// Failing cases print as their key and the expected text, not as bytes.
void PrintTo(const RejectedCase& c, std::ostream* out)
{
    *out << c.key << " (" << c.fragment << ")";
}

class ConfigRejects : public ::testing::TestWithParam<RejectedCase> {};

TEST_P(ConfigRejects, NamesKeyFileAndLine)
{
    const RejectedCase& c = GetParam();
    const auto problems = problemsOf(c.yaml);
    ASSERT_EQ(problems.size(), 1u) << "yaml:\n" << c.yaml << "problems:\n" << joined(problems);
    const std::string prefix = "t.yaml:" + std::to_string(c.line) + ": " + c.key + ": ";
    EXPECT_EQ(problems[0].rfind(prefix, 0), 0u) << problems[0] << "\nexpected prefix " << prefix;
    EXPECT_NE(problems[0].find(c.fragment), std::string::npos)
        << problems[0] << "\nexpected to contain " << c.fragment;
}

const std::string kLongSocketPath = "/run/" + std::string(120, 'x') + ".sock";

INSTANTIATE_TEST_SUITE_P(
    Values, ConfigRejects,
    ::testing::Values(
        // source
        RejectedCase{"source:\n  type: usb\n", "source.type", 2,
                     "unknown value (got usb, expected replay, v4l2, side_by_side or ros2"},
        RejectedCase{"source:\n  ring_capacity: 1\n", "source.ring_capacity", 2,
                     "out of range (got 1, expected 2 to 64 pairs)"},
        RejectedCase{"source:\n  ring_capacity: 65\n", "source.ring_capacity", 2, "got 65"},
        RejectedCase{"source:\n  max_skew_ms: 0\n", "source.max_skew_ms", 2,
                     "expected > 0 and <= 1000 ms"},
        RejectedCase{"source:\n  stall_timeout_ms: 50\n", "source.stall_timeout_ms", 2,
                     "expected 100 to 600000 ms"},
        RejectedCase{"source:\n  replay:\n    fps: -10\n", "source.replay.fps", 3, "got -10"},
        RejectedCase{"source:\n  replay:\n    pacing: fast\n", "source.replay.pacing", 3,
                     "expected paced or lockstep"},
        RejectedCase{"source:\n  replay:\n    loop: maybe\n", "source.replay.loop", 3,
                     "not true or false"},
        RejectedCase{"source:\n  replay:\n    colour: grey\n", "source.replay.colour", 3,
                     "unknown value (got grey, expected left, both or none"},
        RejectedCase{"source:\n  ros2:\n    topics:\n      left: stereo/left\n",
                     "source.ros2.topics.left", 4, "an absolute ROS 2 topic name"},
        RejectedCase{"source:\n  ros2:\n    topics:\n      right: /\n", "source.ros2.topics.right",
                     4, "names no topic"},
        RejectedCase{"source:\n  ros2:\n    topics:\n      right: /stereo/left/image_raw\n",
                     "source.ros2.topics.right", 4, "the same topic as source.ros2.topics.left"},
        RejectedCase{"source:\n  ros2:\n    width: 9000\n", "source.ros2.width", 3,
                     "expected 16 to 8192 px"},
        RejectedCase{"source:\n  ros2:\n    topics:\n      left_camera_info: camera_info\n",
                     "source.ros2.topics.left_camera_info", 4, "an absolute ROS 2 topic name"},
        RejectedCase{"source:\n  ros2:\n    topics:\n      right_camera_info: "
                     "/stereo/left/camera_info\n",
                     "source.ros2.topics.right_camera_info", 4,
                     "the same topic as the left camera's camera_info (/stereo/left/camera_info)"},
        RejectedCase{"source:\n  ros2:\n    topics:\n      right_camera_info: [a]\n",
                     "source.ros2.topics.right_camera_info", 4, "expected auto or text"},
        RejectedCase{"source:\n  type: ros2\nros2:\n  enabled: true\n  namespace: /stereo\n",
                     "ros2.namespace", 5,
                     "stereod would publish its rectified camera_info on /stereo/left/camera_info"},
        RejectedCase{"source: 5\n", "source", 1,
                     "not a section (got 5, expected a mapping of keys)"},
        // matcher
        RejectedCase{"matcher:\n  algorithm: sgmb\n", "matcher.algorithm", 2, "did you mean sgbm?"},
        RejectedCase{"matcher:\n  min_depth_m: 0\n", "matcher.min_depth_m", 2,
                     "expected > 0 and <= 1000 m"},
        RejectedCase{"matcher:\n  min_depth_m: far\n", "matcher.min_depth_m", 2,
                     "not a number (got far, expected a number, in m)"},
        RejectedCase{"matcher:\n  num_disparities: 100\n", "matcher.num_disparities", 2,
                     "not a multiple of 16"},
        RejectedCase{"matcher:\n  num_disparities: -16\n", "matcher.num_disparities", 2,
                     "out of range"},
        RejectedCase{"matcher:\n  num_disparities: 2048\n", "matcher.num_disparities", 2,
                     "got 2048"},
        RejectedCase{"matcher:\n  num_disparities: lots\n", "matcher.num_disparities", 2,
                     "not auto or an integer"},
        RejectedCase{"matcher:\n  max_num_disparities: 250\n", "matcher.max_num_disparities", 2,
                     "not a multiple of 16"},
        RejectedCase{"matcher:\n  max_num_disparities: 0\n", "matcher.max_num_disparities", 2,
                     "out of range"},
        RejectedCase{"matcher:\n  min_disparity: 2000\n", "matcher.min_disparity", 2, "got 2000"},
        RejectedCase{"matcher:\n  num_disparities: 512\n", "matcher.num_disparities", 2,
                     "census-sgm searches at most 256 disparities (got 512, expected"},
        RejectedCase{"matcher:\n  max_num_disparities: 512\n", "matcher.max_num_disparities", 2,
                     "census-sgm searches at most 256 disparities (got 512"},
        // census-sgm's own refusal: the matcher names its field, the configuration the key.
        RejectedCase{"matcher:\n  p2: 250\n", "matcher.p2", 2, "census cost"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  block_size: 4\n", "matcher.block_size", 3,
                     "not odd"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  block_size: 33\n", "matcher.block_size", 3,
                     "1 to 31 px for sgbm"},
        RejectedCase{"matcher:\n  block_size: 5.5\n", "matcher.block_size", 2, "not an integer"},
        RejectedCase{"matcher:\n  block_size: 0x10\n", "matcher.block_size", 2, "not an integer"},
        RejectedCase{"matcher:\n  block_size: [5]\n", "matcher.block_size", 2, "got a list"},
        RejectedCase{"matcher:\n  algorithm: bm\n  block_size: 3\n", "matcher.block_size", 3,
                     "5 to 255 px for bm"},
        // Far beyond: refused by name, not overflowed on the way (its automatic penalties).
        RejectedCase{"matcher:\n  algorithm: bm\n  block_size: 2113092847\n", "matcher.block_size",
                     3, "5 to 255 px for bm"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  block_size: -2113092847\n",
                     "matcher.block_size", 3, "1 to 31 px for sgbm"},
        RejectedCase{"matcher:\n  tuning: flat\n", "matcher.tuning", 2,
                     "unknown value (got flat, expected natural, planar or patterns"},
        RejectedCase{"matcher:\n  uniqueness_ratio: 101\n", "matcher.uniqueness_ratio", 2,
                     "0 to 100 percent"},
        RejectedCase{"matcher:\n  speckle_window_px: -1\n", "matcher.speckle_window_px", 2,
                     "got -1"},
        RejectedCase{"matcher:\n  speckle_range_px: -2\n", "matcher.speckle_range_px", 2, "got -2"},
        RejectedCase{"matcher:\n  lr_max_diff_px: -2\n", "matcher.lr_max_diff_px", 2, "-1 (off)"},
        RejectedCase{"matcher:\n  p1: 0\n", "matcher.p1", 2, "auto or an integer from 1 to 32767"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  p2: 40000\n", "matcher.p2", 3, "got 40000"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  p2: 100\n", "matcher.p2", 3,
                     "not above matcher.p1 (got 100, expected > 200"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  p1: 300\n  p2: 200\n", "matcher.p2", 4,
                     "expected > 300"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  p1: 900\n", "matcher.p1", 3,
                     "not below the automatic p2"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  pre_filter_cap: 64\n",
                     "matcher.pre_filter_cap", 3, "1 to 63"},
        RejectedCase{"matcher:\n  algorithm: sgbm\n  texture_threshold: -1\n",
                     "matcher.texture_threshold", 3, "got -1"},
        RejectedCase{"matcher:\n  blok_size: 5\n", "matcher.blok_size", 2,
                     "unknown key (did you mean block_size?)"},
        RejectedCase{"matcher:\n  min_pixels: 5\n", "matcher.min_pixels", 2,
                     "did you mean nearest.min_pixels?"},
        RejectedCase{"matcher:\n  wavelength: red\n", "matcher.wavelength", 2,
                     "known keys here: algorithm, min_depth_m"},
        // nearest
        RejectedCase{"nearset:\n  min_pixels: 5\n", "nearset", 1, "did you mean nearest?"},
        RejectedCase{"nearest:\n  roi:\n    x: 1.0\n", "nearest.roi.x", 3,
                     "expected >= 0 and < 1 of the image width"},
        RejectedCase{"nearest:\n  roi:\n    y: -0.1\n", "nearest.roi.y", 3, "got -0.1"},
        RejectedCase{"nearest:\n  roi:\n    width: 0\n", "nearest.roi.width", 3, "out of range"},
        RejectedCase{"nearest:\n  roi:\n    heigth: 0.5\n", "nearest.roi.heigth", 3,
                     "did you mean height?"},
        RejectedCase{"nearest:\n  roi: {x: 0.6, y: 0.1, width: 0.5, height: 0.5}\n",
                     "nearest.roi.width", 2, "right edge of the image (got 0.5, expected <= 0.4"},
        RejectedCase{"nearest:\n  roi:\n    y: 0.7\n    height: 0.5\n", "nearest.roi.height", 4,
                     "bottom edge"},
        RejectedCase{"nearest:\n  min_depth_m: -0.5\n", "nearest.min_depth_m", 2, "got -0.5"},
        RejectedCase{"nearest:\n  max_depth_m: 0.05\n", "nearest.max_depth_m", 2,
                     "not above nearest.min_depth_m (got 0.05, expected > 0.1 m)"},
        RejectedCase{"nearest:\n  max_depth_m: inf\n", "nearest.max_depth_m", 2,
                     "not a finite number"},
        RejectedCase{"nearest:\n  percentile: 101\n", "nearest.percentile", 2, "0 to 100 percent"},
        RejectedCase{"nearest:\n  min_valid_fraction: 1.5\n", "nearest.min_valid_fraction", 2,
                     "0 to 1"},
        RejectedCase{"nearest:\n  min_pixels: 0\n", "nearest.min_pixels", 2, "got 0"},
        RejectedCase{"point_cloud: 1\n", "point_cloud", 1, "not true or false (got 1"},
        // socket
        RejectedCase{"socket:\n  path: \"\"\n", "socket.path", 2, "empty"},
        RejectedCase{"socket:\n  path: " + kLongSocketPath + "\n", "socket.path", 2,
                     "too long for a Unix socket"},
        RejectedCase{"socket:\n  mode: \"0690\"\n", "socket.mode", 2, "not an octal file mode"},
        RejectedCase{"socket:\n  mode: 1777\n", "socket.mode", 2, "out of range (got \"1777\""},
        RejectedCase{"socket:\n  group: no-such-group-for-stereod\n", "socket.group", 2,
                     "no such group"},
        RejectedCase{"socket:\n  max_clients: 0\n", "socket.max_clients", 2, "1 to 1024"},
        RejectedCase{"socket:\n  max_request_bytes: 100\n", "socket.max_request_bytes", 2,
                     "1024 to 16777216 bytes"},
        RejectedCase{"socket:\n  max_request_bytes: -1\n", "socket.max_request_bytes", 2,
                     "out of range"},
        RejectedCase{"socket:\n  idle_timeout_s: -1\n", "socket.idle_timeout_s", 2, "got -1"},
        // publish, log level, paths
        RejectedCase{"publish:\n  readings_max_hz: -1\n", "publish.readings_max_hz", 2,
                     "0 to 1000 Hz"},
        RejectedCase{"publish:\n  depth_max_hz: 5000\n", "publish.depth_max_hz", 2, "got 5000"},
        RejectedCase{"publish:\n  max_client_backlog_bytes: 1000\n",
                     "publish.max_client_backlog_bytes", 2, "expected >= 1048576 bytes"},
        RejectedCase{"publish:\n  max_client_backlog_bytes: 5000000000\n",
                     "publish.max_client_backlog_bytes", 2, "out of range"},
        RejectedCase{"publish:\n  max_reading_age_ms: 0\n", "publish.max_reading_age_ms", 2,
                     "got 0"},
        RejectedCase{"log_level: inf\n", "log_level", 1,
                     "unknown level (got inf, expected trace, debug"},
        RejectedCase{"log_level: inf\n", "log_level", 1, "did you mean info?"},
        RejectedCase{"calibration: {file: a.yaml}\n", "calibration", 1, "not text (got a mapping"},
        RejectedCase{"calibration: /nonexistent/stereod/calibration.yaml\n", "calibration", 1,
                     "does not exist (got /nonexistent/stereod/calibration.yaml"},
        RejectedCase{"source:\n  replay:\n    path: /nonexistent/stereod/recording\n",
                     "source.replay.path", 3, "does not exist (got /nonexistent/stereod/recording"},
        RejectedCase{"matcher:\n  block_size: 5\n  block_size: 7\n", "matcher.block_size", 3,
                     "given twice (first on line 2"}));

TEST(ConfigErrors, EveryProblemIsReportedAtOnce)
{
    // Found by different passes (ranges after types), listed in the order of the file.
    const std::string yaml = "matcher:\n"
                             "  min_depth_m: -1\n" // line 2: out of range
                             "  blok_size: 5\n"    // line 3: unknown key
                             "nearest:\n"
                             "  percentile: lots\n"; // line 5: wrong type
    const auto problems = problemsOf(yaml, "robot.yaml");
    ASSERT_EQ(problems.size(), 3u) << joined(problems);
    EXPECT_EQ(problems[0].rfind("robot.yaml:2: matcher.min_depth_m: ", 0), 0u) << problems[0];
    EXPECT_EQ(problems[1].rfind("robot.yaml:3: matcher.blok_size: ", 0), 0u) << problems[1];
    EXPECT_EQ(problems[2].rfind("robot.yaml:5: nearest.percentile: ", 0), 0u) << problems[2];

    try {
        parseConfig(yaml, "robot.yaml");
        FAIL();
    } catch (const ConfigError& error) {
        // what() is ready to print: the same problems, one per line.
        EXPECT_EQ(std::string(error.what()) + "\n", joined(problems));
    }
}

TEST(ConfigErrors, AKeyThatCouldNotBeReadDoesNotSpawnFollowUpProblems)
{
    // max_depth_m unreadable: no "not above min_depth_m" against its default as well.
    const auto problems = problemsOf("nearest:\n  min_depth_m: 30\n  max_depth_m: far\n");
    ASSERT_EQ(problems.size(), 1u) << joined(problems);
    EXPECT_NE(problems[0].find("nearest.max_depth_m: not a number"), std::string::npos);
}

TEST(ConfigErrors, SyntaxErrorGivesFileAndLine)
{
    const auto unclosed = problemsOf("matcher:\n  block_size: 5\n  p1: [8\nnearest: {}\n");
    ASSERT_EQ(unclosed.size(), 1u) << joined(unclosed);
    // The list opened on line 3 is found unclosed where the next line ends it.
    EXPECT_EQ(unclosed[0],
              "t.yaml:4: YAML syntax error at column 8: end of sequence flow not found");

    const auto bad_indent = problemsOf("matcher:\n  block_size: 5\n block: 7\n");
    ASSERT_EQ(bad_indent.size(), 1u) << joined(bad_indent);
    EXPECT_EQ(bad_indent[0].rfind("t.yaml:3: YAML syntax error at column", 0), 0u) << bad_indent[0];
}

TEST(ConfigErrors, TopLevelMustBeAMappingAndASingleDocument)
{
    const auto scalar = problemsOf("just some text\n");
    ASSERT_EQ(scalar.size(), 1u) << joined(scalar);
    EXPECT_EQ(scalar[0], "t.yaml:1: not a mapping of keys (got \"just some text\", expected a "
                         "mapping of keys)");

    const auto two = problemsOf("log_level: info\n---\nlog_level: debug\n");
    ASSERT_EQ(two.size(), 1u) << joined(two);
    EXPECT_EQ(two[0].rfind("t.yaml:2: a second YAML document", 0), 0u) << two[0];
}

// Found by fuzzing: yaml-cpp 0.7's LoadAll() never returns on a lone ",", producing
// documents without end. The loader must return, and refuse the text.
TEST(ConfigErrors, InputThatStallsYamlCppIsRefused)
{
    for (const std::string text : {",", ",\n,\n", "# comment\n,\n"}) {
        const auto problems = problemsOf(text);
        ASSERT_EQ(problems.size(), 1u) << joined(problems);
        EXPECT_EQ(problems[0].rfind("t.yaml:", 0), 0u) << problems[0];
    }
}

TEST(ConfigErrors, ValuesAreShownOnOneLine)
{
    const auto problems = problemsOf("log_level: \"a\\nb\\u0001\\\"\"\n");
    ASSERT_EQ(problems.size(), 1u) << joined(problems);
    EXPECT_EQ(problems[0].find('\n'), std::string::npos) << problems[0];
    EXPECT_NE(problems[0].find("got \"a\\nb\\x01\\\"\""), std::string::npos) << problems[0];
}

TEST(ConfigErrors, MissingFileIsNamed)
{
    const std::string path = "/nonexistent/stereod/robot.yaml";
    try {
        loadConfig(path);
        FAIL() << "loaded a file that does not exist";
    } catch (const ConfigError& error) {
        ASSERT_EQ(error.problems().size(), 1u);
        EXPECT_EQ(error.problems()[0],
                  path + ": cannot read the configuration: No such file or directory");
    }
    test::TempDir dir;
    try {
        loadConfig(dir.path());
        FAIL() << "loaded a directory";
    } catch (const ConfigError& error) {
        EXPECT_NE(std::string(error.what()).find("is a directory"), std::string::npos);
    }
}

TEST(ConfigValues, NumbersAreDecimalAndModesOctal)
{
    EXPECT_EQ(parseConfig("matcher:\n  block_size: 09\n", "t").processing.matcher.block_size, 9);
    EXPECT_EQ(parseConfig("matcher:\n  block_size: +7\n", "t").processing.matcher.block_size, 7);
    EXPECT_EQ(
        parseConfig("matcher:\n  num_disparities: 64\n", "t").processing.matcher.num_disparities,
        64);
    EXPECT_FALSE(parseConfig("matcher:\n  p1: auto\n", "t").processing.matcher.p1);
    for (const std::string mode : {"\"0660\"", "0660", "660", "0o660"}) {
        EXPECT_EQ(parseConfig("socket:\n  mode: " + mode + "\n", "t").socket.mode, 0660u) << mode;
    }
    EXPECT_EQ(parseConfig("socket:\n  mode: \"0600\"\n", "t").socket.mode, 0600u);
    EXPECT_FALSE(parseConfig("point_cloud: off\n", "t").processing.compute_cloud);
    EXPECT_EQ(parseConfig("source:\n  replay:\n    pacing: lockstep\n", "t").source.replay.pacing,
              ReplayPacing::Lockstep);
    for (const auto& [name, colour] :
         {std::pair{"none", CameraColour::None}, std::pair{"left", CameraColour::Left},
          std::pair{"both", CameraColour::Both}}) {
        EXPECT_EQ(parseConfig(std::string("source:\n  replay:\n    colour: ") + name + "\n", "t")
                      .source.replay.colour,
                  colour)
            << name;
    }
    const ServiceConfig bm = parseConfig("matcher:\n  algorithm: bm\n  block_size: 15\n", "t");
    EXPECT_EQ(bm.processing.matcher.kind, MatcherKind::Bm);
    const ServiceConfig hh = parseConfig("matcher:\n  algorithm: sgbm-3way\n", "t");
    EXPECT_EQ(hh.processing.matcher.sgbm_mode, SgbmMode::ThreeWay);
    // 0.3 + 0.7 is not exactly 1 in binary; the region still reaches the edge.
    EXPECT_NO_THROW(
        parseConfig("nearest:\n  roi: {x: 0.3, y: 0.1, width: 0.7, height: 0.9}\n", "t"));
    // An empty section keeps its defaults.
    EXPECT_TRUE(
        diffConfig(defaultConfig(), parseConfig("nearest:\nsocket:\n", "t")).changed.empty());
}

TEST(ConfigPaths, RelativePathsResolveAgainstTheFilesDirectory)
{
    test::TempDir dir;
    fs::create_directories(fs::path(dir.path()) / "recordings/run1");
    dir.write("calib/rig.yaml", "focal_px: 500\n");
    const fs::path file =
        dir.write("etc/robot.yaml", "source:\n  replay:\n    path: ../recordings/run1\n"
                                    "calibration: ../calib/rig.yaml\n"
                                    "socket:\n  path: run/stereod.sock\n");
    const ServiceConfig config = loadConfig(file.string());
    EXPECT_EQ(config.origin, file.string());
    EXPECT_EQ(config.source.replay.path, (fs::path(dir.path()) / "recordings/run1").string());
    EXPECT_EQ(config.calibration_path, (fs::path(dir.path()) / "calib/rig.yaml").string());
    EXPECT_EQ(config.socket.path, (fs::path(dir.path()) / "etc/run/stereod.sock").string());

    // Absolute paths stay as written.
    const fs::path absolute = dir.write(
        "abs.yaml", "calibration: " + (fs::path(dir.path()) / "calib/rig.yaml").string() + "\n");
    EXPECT_EQ(loadConfig(absolute.string()).calibration_path,
              (fs::path(dir.path()) / "calib/rig.yaml").string());
}

TEST(ConfigPaths, ARecordingWithoutCalibrationRunsUncalibrated)
{
    test::TempDir dir;
    fs::create_directories(fs::path(dir.path()) / "plain");
    const fs::path file = dir.write("robot.yaml", "source:\n  replay:\n    path: plain\n");
    // No calibration anywhere is the uncalibrated mode of a robot's first start.
    EXPECT_EQ(loadConfig(file.string()).calibration_path, "");
    dir.write("plain/calibration.yaml", "focal_px: 500\n");
    EXPECT_NO_THROW(loadConfig(file.string()));
    // A calibration that is named must exist.
    const fs::path named = dir.write("named.yaml", "calibration: missing.yaml\n");
    try {
        loadConfig(named.string());
        FAIL() << "accepted a calibration file that does not exist";
    } catch (const ConfigError& error) {
        ASSERT_EQ(error.problems().size(), 1u) << error.what();
        EXPECT_NE(error.problems()[0].find("calibration"), std::string::npos)
            << error.problems()[0];
    }

    // A path that is a file, neither a directory nor an MCAP bag.
    const fs::path wrong = dir.write("wrong.yaml", "source:\n  replay:\n    path: robot.yaml\n");
    try {
        loadConfig(wrong.string());
        FAIL();
    } catch (const ConfigError& error) {
        ASSERT_EQ(error.problems().size(), 1u) << error.what();
        EXPECT_NE(error.problems()[0].find(
                      ":3: source.replay.path: is neither a directory nor an MCAP file"),
                  std::string::npos)
            << error.problems()[0];
    }
}

TEST(ConfigOverrides, CommandLineValuesReplaceTheFileAndAreNamedInProblems)
{
    test::TempDir dir;
    fs::create_directories(fs::path(dir.path()) / "rec");
    dir.write("rec/calibration.yaml", "focal_px: 500\n");
    // The file's own recording does not exist on this machine; --replay replaces it.
    const fs::path file =
        dir.write("robot.yaml", "source:\n  replay:\n    path: /nonexistent/stereod/rec\n");
    EXPECT_THROW(loadConfig(file.string()), ConfigError);

    ConfigOverrides overrides;
    overrides.replay_path = (fs::path(dir.path()) / "rec").string();
    overrides.socket_path = (fs::path(dir.path()) / "s.sock").string();
    overrides.log_level = "debug";
    const ServiceConfig config = loadConfig(file.string(), overrides);
    EXPECT_EQ(config.source.replay.path, overrides.replay_path);
    EXPECT_EQ(config.socket.path, overrides.socket_path);
    EXPECT_EQ(config.log_level, "debug");

    ConfigOverrides bad;
    bad.replay_path = "/nonexistent/stereod/other";
    bad.log_level = "loud";
    try {
        loadConfig(file.string(), bad);
        FAIL();
    } catch (const ConfigError& error) {
        ASSERT_EQ(error.problems().size(), 2u) << error.what();
        EXPECT_EQ(error.problems()[0].rfind("command line (--replay): source.replay.path: does "
                                            "not exist (got /nonexistent/stereod/other",
                                            0),
                  0u)
            << error.problems()[0];
        EXPECT_EQ(error.problems()[1].rfind("command line (--log-level): log_level: unknown", 0),
                  0u)
            << error.problems()[1];
    }
}

// Issue 23: without a file, a bad --live-view was blamed on "<defaults>". Given the
// overrides, the message names the option, as a file's does.
TEST(ConfigOverrides, ProblemsOfOverriddenValuesNameTheOptionWithoutAFile)
{
    ServiceConfig config = defaultConfig();
    ConfigOverrides overrides;
    overrides.live_view = "nonsense";
    applyOverrides(config, overrides);
    try {
        validateConfig(config, overrides);
        FAIL();
    } catch (const ConfigError& error) {
        ASSERT_EQ(error.problems().size(), 1u) << error.what();
        EXPECT_EQ(error.problems()[0].rfind("command line (--live-view): live_view.listen: ", 0),
                  0u)
            << error.problems()[0];
    }
}

TEST(ConfigOverrides, ValidateConfigChecksAnInCodeConfiguration)
{
    test::TempDir dir;
    ServiceConfig config = defaultConfig();
    ConfigOverrides overrides;
    overrides.replay_path = (fs::path(dir.path()) / "missing").string();
    overrides.calibration_path = (fs::path(dir.path()) / "missing.yaml").string();
    applyOverrides(config, overrides);
    config.processing.nearest.percentile = -1;
    try {
        validateConfig(config);
        FAIL();
    } catch (const ConfigError& error) {
        ASSERT_EQ(error.problems().size(), 3u) << error.what();
        EXPECT_EQ(error.problems()[0].rfind("<defaults>: source.replay.path: does not exist (got " +
                                                overrides.replay_path,
                                            0),
                  0u)
            << error.problems()[0];
        EXPECT_EQ(error.problems()[1].rfind("<defaults>: calibration: does not exist (got " +
                                                overrides.calibration_path,
                                            0),
                  0u)
            << error.problems()[1];
        EXPECT_EQ(error.problems()[2].rfind("<defaults>: nearest.percentile: out of range", 0), 0u)
            << error.problems()[2];
    }

    // Relative command-line paths are taken against the working directory, once.
    ServiceConfig relative = defaultConfig();
    ConfigOverrides rel;
    rel.replay_path = "some/recording";
    applyOverrides(relative, rel);
    EXPECT_EQ(relative.source.replay.path, (fs::current_path() / "some/recording").string());

    // In-code values the file could not even hold are caught too.
    ServiceConfig odd = defaultConfig();
    odd.socket.mode = 01777;
    odd.processing.matcher.num_disparities = -16;
    EXPECT_THROW(validateConfig(odd), ConfigError);
}

TEST(ConfigDiff, SeparatesLiveChangesFromThoseNeedingARestart)
{
    const ServiceConfig running = defaultConfig();
    EXPECT_TRUE(diffConfig(running, running).changed.empty());

    ServiceConfig proposed = running;
    proposed.origin = "elsewhere.yaml"; // where it came from is not a setting
    proposed.processing.nearest.roi.x = 0.1;
    proposed.processing.matcher.kind = MatcherKind::Bm;
    proposed.publish.depth_max_hz = 5;
    proposed.log_level = "debug";
    proposed.processing.compute_cloud = false;
    proposed.socket.path = "/tmp/other.sock";
    proposed.calibration_path = "/etc/stereod/rig.yaml";
    proposed.source.replay.pacing = ReplayPacing::Lockstep;

    const ConfigChange change = diffConfig(running, proposed);
    EXPECT_EQ(change.changed,
              (std::vector<std::string>{"source.replay.pacing", "calibration", "matcher.algorithm",
                                        "nearest.roi.x", "point_cloud", "socket.path",
                                        "publish.depth_max_hz", "log_level"}));
    EXPECT_EQ(change.restart_needed,
              (std::vector<std::string>{"source.replay.pacing", "calibration", "socket.path"}));

    // The SGBM mode does not matter once the matcher is BM.
    ServiceConfig bm_other_mode = proposed;
    bm_other_mode.processing.matcher.sgbm_mode = SgbmMode::ThreeWay;
    EXPECT_TRUE(diffConfig(proposed, bm_other_mode).changed.empty());
}

// Each matcher brings its own values for the settings they share, unless the file sets
// them: census-sgm (the default) its tuned ones, OpenCV's matchers OpenCV's.
TEST(ConfigMatcher, EachMatcherTakesItsOwnSharedDefaultsUnlessSet)
{
    EXPECT_EQ(defaultConfig().processing.matcher.kind, MatcherKind::CensusSgm);
    const ServiceConfig census = parseConfig("matcher:\n  algorithm: census-sgm\n", "t.yaml");
    EXPECT_EQ(effectiveMatcherSettings(census.processing.matcher).kind, MatcherKind::CensusSgm);
    EXPECT_EQ(effectiveMatcherSettings(census.processing.matcher).uniqueness_ratio, 9);
    EXPECT_EQ(effectiveMatcherSettings(census.processing.matcher).lr_max_diff_px, 2);
    EXPECT_EQ(effectiveMatcherSettings(census.processing.matcher).speckle_window_px, 200);
    EXPECT_EQ(effectiveMatcherSettings(census.processing.matcher).speckle_range_px, 1);
    const ServiceConfig set =
        parseConfig("matcher:\n  uniqueness_ratio: 12\n  algorithm: census-sgm\n", "t.yaml");
    EXPECT_EQ(effectiveMatcherSettings(set.processing.matcher).uniqueness_ratio, 12);
    EXPECT_EQ(effectiveMatcherSettings(set.processing.matcher).lr_max_diff_px, 2);
    EXPECT_EQ(effectiveMatcherSettings(defaultConfig().processing.matcher).uniqueness_ratio, 9);

    for (const char* opencv : {"sgbm", "sgbm-3way", "bm"}) {
        const MatcherSettings m = effectiveMatcherSettings(
            parseConfig(std::string("matcher:\n  algorithm: ") + opencv + "\n", "t.yaml")
                .processing.matcher);
        EXPECT_EQ(m.uniqueness_ratio, 10) << opencv;
        EXPECT_EQ(m.lr_max_diff_px, 1) << opencv;
        EXPECT_EQ(m.speckle_window_px, 100) << opencv;
        EXPECT_EQ(m.speckle_range_px, 2) << opencv;
    }
    const MatcherSettings sgbm_set = effectiveMatcherSettings(
        parseConfig("matcher:\n  algorithm: sgbm\n  speckle_window_px: 50\n", "t.yaml")
            .processing.matcher);
    EXPECT_EQ(sgbm_set.speckle_window_px, 50);
    EXPECT_EQ(sgbm_set.uniqueness_ratio, 10);
}

// The planar tuning brings its own shared values too (pipeline/matcher_settings.hpp),
// and a value the file sets still wins.
TEST(ConfigMatcher, PlanarTuningTakesItsOwnSharedDefaultsUnlessSet)
{
    EXPECT_EQ(effectiveMatcherSettings(defaultConfig().processing.matcher).tuning,
              MatcherTuning::Natural);
    const MatcherSettings planar = effectiveMatcherSettings(
        parseConfig("matcher:\n  tuning: planar\n", "t.yaml").processing.matcher);
    EXPECT_EQ(planar.tuning, MatcherTuning::Planar);
    EXPECT_EQ(planar.uniqueness_ratio, censusSgmTuning(MatcherTuning::Planar).uniqueness_percent);
    EXPECT_EQ(planar.speckle_window_px, censusSgmTuning(MatcherTuning::Planar).speckle_window_px);
    EXPECT_EQ(planar.speckle_range_px, censusSgmTuning(MatcherTuning::Planar).speckle_range_px);
    EXPECT_EQ(planar.lr_max_diff_px, censusSgmTuning(MatcherTuning::Planar).lr_max_diff_px);
    EXPECT_NE(planar.speckle_window_px,
              effectiveMatcherSettings(defaultConfig().processing.matcher).speckle_window_px);
    const MatcherSettings set = effectiveMatcherSettings(
        parseConfig("matcher:\n  tuning: planar\n  uniqueness_ratio: 9\n", "t.yaml")
            .processing.matcher);
    EXPECT_EQ(set.uniqueness_ratio, 9);
    EXPECT_EQ(set.speckle_window_px, censusSgmTuning(MatcherTuning::Planar).speckle_window_px);
}

// matcher.p2_gradient_scale: left out or `auto`, the tuning decides; a number sets it;
// `off` turns census-sgm's gradient adaptation off (the core gets 0), and shows as off.
TEST(ConfigMatcher, GradientScaleIsAutoANumberOrOff)
{
    const auto matcher = [](const std::string& yaml) {
        return parseConfig(yaml, "t.yaml").processing.matcher;
    };
    const DisparityRange range{0, 64};
    const MatcherSettings absent = matcher("matcher:\n  min_depth_m: 0.5\n");
    EXPECT_FALSE(absent.p2_gradient_scale);
    EXPECT_EQ(censusSgmSettings(absent, range).p2_gradient_scale, 3);
    const MatcherSettings automatic = matcher("matcher:\n  p2_gradient_scale: auto\n");
    EXPECT_FALSE(automatic.p2_gradient_scale);
    EXPECT_EQ(censusSgmSettings(automatic, range).p2_gradient_scale, 3);
    const MatcherSettings number = matcher("matcher:\n  p2_gradient_scale: 6\n");
    EXPECT_EQ(number.p2_gradient_scale, 6);
    EXPECT_EQ(censusSgmSettings(number, range).p2_gradient_scale, 6);
    const MatcherSettings off = matcher("matcher:\n  p2_gradient_scale: off\n");
    EXPECT_EQ(off.p2_gradient_scale, 0);
    EXPECT_EQ(censusSgmSettings(off, range).p2_gradient_scale, 0);
    // The planar tuning's automatic value is already off; a number turns it on.
    EXPECT_EQ(censusSgmSettings(matcher("matcher:\n  tuning: planar\n"), range).p2_gradient_scale,
              0);
    EXPECT_EQ(
        censusSgmSettings(matcher("matcher:\n  tuning: planar\n  p2_gradient_scale: 4\n"), range)
            .p2_gradient_scale,
        4);

    // A bad value names the key, the file and its line, and what would do.
    for (const std::string value : {"none", "0", "-3"}) {
        try {
            parseConfig("matcher:\n  p2_gradient_scale: " + value + "\n", "robot.yaml");
            FAIL() << value;
        } catch (const ConfigError& error) {
            const std::string what = error.what();
            EXPECT_NE(what.find("robot.yaml:2"), std::string::npos) << what;
            EXPECT_NE(what.find("matcher.p2_gradient_scale"), std::string::npos) << what;
            EXPECT_NE(what.find("auto, off or grey levels"), std::string::npos) << what;
        }
    }
}

// The shared settings take `auto` too, which is the same as leaving them out.
TEST(ConfigMatcher, SharedSettingsTakeAuto)
{
    const MatcherSettings m = parseConfig("matcher:\n  algorithm: sgbm\n  uniqueness_ratio: auto\n"
                                          "  lr_max_diff_px: -1\n",
                                          "t.yaml")
                                  .processing.matcher;
    EXPECT_FALSE(m.uniqueness_ratio);
    EXPECT_EQ(effectiveMatcherSettings(m).uniqueness_ratio, 10);
    EXPECT_EQ(m.lr_max_diff_px, -1);
}

// source.type ros2 takes its calibration from the camera_info topics beside the image
// topics unless others are given; stereod's own node must not publish on them.
TEST(ConfigRos2Source, CameraInfoTopicsAreBesideTheImagesUnlessGiven)
{
    // The two camera_info topics of the ros2 source given by `topics_yaml`.
    const auto infoTopics = [](const std::string& topics_yaml) {
        const Ros2SourceConfig ros2 =
            parseConfig("source:\n  ros2:\n    topics:\n" + topics_yaml, "t.yaml").source.ros2;
        return std::vector<std::string>{leftCameraInfoTopic(ros2), rightCameraInfoTopic(ros2)};
    };
    const ServiceConfig defaults = defaultConfig();
    EXPECT_FALSE(defaults.source.ros2.left_info_topic.has_value());
    EXPECT_EQ(infoTopics("      left: /stereo/left/image_raw\n"),
              (std::vector<std::string>{"/stereo/left/camera_info", "/stereo/right/camera_info"}));
    EXPECT_EQ(
        infoTopics("      left: /cam/left/image_color\n      right: /cam/right/image_color\n"),
        (std::vector<std::string>{"/cam/left/camera_info", "/cam/right/camera_info"}));
    const std::string given_yaml =
        "      left_camera_info: /rig/info_l\n      right_camera_info: auto\n";
    EXPECT_EQ(infoTopics(given_yaml),
              (std::vector<std::string>{"/rig/info_l", "/stereo/right/camera_info"}));
    const ServiceConfig given =
        parseConfig("source:\n  ros2:\n    topics:\n" + given_yaml, "t.yaml");
    const ConfigChange change = diffConfig(defaults, given);
    EXPECT_EQ(change.changed, (std::vector<std::string>{"source.ros2.topics.left_camera_info"}));
    EXPECT_EQ(change.restart_needed, change.changed);

    // stereod's node beside a driver under one namespace: refused only while the
    // calibration comes from camera_info.
    EXPECT_TRUE(problemsOf("source:\n  type: ros2\nros2:\n  enabled: true\n  namespace: "
                           "/stereo_depth\n")
                    .empty());
    ServiceConfig with_file = defaultConfig();
    with_file.source.kind = SourceKind::Ros2;
    with_file.ros2.enabled = true;
    // Any file that exists: the calibration's content is start-up's to check.
    with_file.calibration_path = (fs::path(STEREOD_SOURCE_DIR) / "README.md").string();
    EXPECT_NO_THROW(validateConfig(with_file)) << "a calibration file: no camera_info read";
}

TEST(ConfigDiff, EveryKeyIsClassified)
{
    const auto keys = configKeys();
    ASSERT_GE(keys.size(), 40u);
    for (const auto& key : keys) {
        const bool restart = key.path.rfind("source.", 0) == 0 || key.path == "calibration" ||
                             key.path.rfind("socket.", 0) == 0 ||
                             key.path.rfind("live_view.", 0) == 0 ||
                             key.path.rfind("ros2.", 0) == 0;
        EXPECT_EQ(key.live, !restart) << key.path;
    }
}

TEST(ConfigSocket, AllowListsAreListsOfNumericIds)
{
    const ServiceConfig config =
        parseConfig("socket:\n  allow_uids: [1000, 0]\n  allow_gids:\n    - 27\n", "t.yaml");
    EXPECT_EQ(config.socket.allow_uids, (std::vector<uint32_t>{1000, 0}));
    EXPECT_EQ(config.socket.allow_gids, (std::vector<uint32_t>{27}));
    const ConfigChange change = diffConfig(defaultConfig(), config);
    EXPECT_EQ(change.changed, (std::vector<std::string>{"socket.allow_uids", "socket.allow_gids"}));
    EXPECT_EQ(change.restart_needed, change.changed);
    EXPECT_TRUE(parseConfig("socket:\n  allow_uids: []\n  allow_gids:\n", "t.yaml")
                    .socket.allow_uids.empty());

    for (const std::string list : {"1000", "[-1]", "[4294967295]", "[root]", "[[1]]", "{a: 1}"}) {
        const auto problems = problemsOf("socket:\n  allow_uids: " + list + "\n");
        ASSERT_EQ(problems.size(), 1u) << list;
        EXPECT_NE(problems[0].find("t.yaml:2: socket.allow_uids: "), std::string::npos)
            << problems[0];
        EXPECT_NE(problems[0].find("numeric ids"), std::string::npos) << problems[0];
    }
}

TEST(ConfigDocs, EveryKeyIsDocumented)
{
    const std::string docs = readText(fs::path(STEREOD_SOURCE_DIR) / "docs/configuration.md");
    ASSERT_FALSE(docs.empty());
    for (const auto& key : configKeys()) {
        EXPECT_NE(docs.find("`" + key.path + "`"), std::string::npos)
            << key.path << " is not in docs/configuration.md";
    }
}

TEST(ConfigOutput, MaxDepthIsAutoOrMetresAboveZero)
{
    EXPECT_FALSE(defaultConfig().processing.output.max_depth_m.has_value());
    EXPECT_FALSE(parseConfig("output:\n  max_depth_m: auto\n", "t.yaml")
                     .processing.output.max_depth_m.has_value());
    const ServiceConfig set = parseConfig("output:\n  max_depth_m: 12.5\n", "t.yaml");
    EXPECT_EQ(set.processing.output.max_depth_m, 12.5);
    const ConfigChange change = diffConfig(defaultConfig(), set);
    EXPECT_EQ(change.changed, std::vector<std::string>{"output.max_depth_m"});
    EXPECT_TRUE(change.restart_needed.empty()); // live
    for (const std::string value : {"0", "-3", "far", "[1]"}) {
        const auto problems = problemsOf("output:\n  max_depth_m: " + value + "\n");
        ASSERT_EQ(problems.size(), 1u) << value;
        EXPECT_NE(problems[0].find("t.yaml:2: output.max_depth_m: "), std::string::npos)
            << problems[0];
    }
}

TEST(ConfigLiveView, ListenAddressRatesAndTheirLimits)
{
    const ServiceConfig defaults = defaultConfig();
    EXPECT_EQ(defaults.live_view.listen, "127.0.0.1:8765");
    EXPECT_EQ(defaults.live_view.rate_hz.points, 0.0); // follows max_rate_hz
    const ServiceConfig set = parseConfig("live_view:\n  listen: off\n  max_rate_hz: 30\n  "
                                          "rate_hz:\n    points: 2\n    nearest: 60\n",
                                          "t.yaml");
    EXPECT_EQ(set.live_view.listen, "off");
    EXPECT_EQ(set.live_view.max_rate_hz, 30.0);
    EXPECT_EQ(set.live_view.rate_hz.points, 2.0);
    EXPECT_EQ(set.live_view.rate_hz.nearest, 60.0);
    EXPECT_EQ(set.live_view.rate_hz.depth, 0.0);
    const ConfigChange change = diffConfig(defaults, set);
    EXPECT_EQ(change.restart_needed, change.changed);
    EXPECT_NE(std::find(change.changed.begin(), change.changed.end(), "live_view.rate_hz.points"),
              change.changed.end());

    for (const auto& [yaml, expected] : std::vector<std::pair<std::string, std::string>>{
             {"live_view:\n  rate_hz:\n    points: -1\n", "t.yaml:3: live_view.rate_hz.points: "},
             {"live_view:\n  rate_hz:\n    depth: 1001\n", "t.yaml:3: live_view.rate_hz.depth: "},
             {"live_view:\n  rate_hz:\n    pointz: 2\n", "live_view.rate_hz.pointz"},
             {"live_view:\n  max_rate_hz: 0\n", "t.yaml:2: live_view.max_rate_hz: "},
             {"live_view:\n  listen: 8765\n", "t.yaml:2: live_view.listen: "}}) {
        const auto problems = problemsOf(yaml);
        ASSERT_EQ(problems.size(), 1u) << yaml;
        EXPECT_NE(problems[0].find(expected), std::string::npos) << problems[0];
    }
}

} // namespace
} // namespace stereod
