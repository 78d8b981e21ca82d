// The command line of `stereoctl` without a service: calibrate, help, argument errors,
// and the exit code 3 of every client command when the service cannot be reached.

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/calibration.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::ProcessResult;
using test::runProcess;
using test::stereoctlPath;

TEST(StereoctlCalibrate, RectifiedFileReadsBackWithTheSameNumbers)
{
    test::TempDir dir;
    const std::string out = dir.file("aloe.yaml");
    const ProcessResult run =
        runProcess({stereoctlPath(), "calibrate", "--rectified", "--focal-px", "3740",
                    "--baseline-m", "0.16", "--size", "1282x1110", "--cx", "640.25", "--cy",
                    "554.5", "--doffs-px", "270", "--out", out});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_NE(run.out.find(out), std::string::npos) << run.out;

    const StereoCalibration loaded = loadCalibration(out);
    EXPECT_EQ(loaded.kind, StereoCalibration::Kind::RectifiedOnly);
    const RectifiedGeometry& g = loaded.rectified;
    EXPECT_EQ(g.image_size, (ImageSize{1282, 1110}));
    EXPECT_DOUBLE_EQ(g.focal_px, 3740.0);
    EXPECT_DOUBLE_EQ(g.baseline_m, 0.16);
    EXPECT_DOUBLE_EQ(g.cx_px, 640.25);
    EXPECT_DOUBLE_EQ(g.cy_px, 554.5);
    EXPECT_DOUBLE_EQ(g.doffs_px, 270.0);
}

TEST(StereoctlCalibrate, PrincipalPointDefaultsAsTheLibraryDoes)
{
    test::TempDir dir;
    const std::string out = dir.file("tsukuba.yaml");
    const ProcessResult run =
        runProcess({stereoctlPath(), "calibrate", "--rectified", "--focal-px", "615",
                    "--baseline-m", "0.1", "--size", "384x288", "--out", out});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const RectifiedGeometry expected =
        makeRectifiedCalibration(cv::Size(384, 288), 615.0, 0.1).rectified;
    const RectifiedGeometry g = loadCalibration(out).rectified;
    EXPECT_DOUBLE_EQ(g.cx_px, expected.cx_px);
    EXPECT_DOUBLE_EQ(g.cy_px, expected.cy_px);
    EXPECT_DOUBLE_EQ(g.doffs_px, 0.0);
}

TEST(StereoctlCalibrate, BadArgumentsExitTwo)
{
    test::TempDir dir;
    const std::string out = dir.file("c.yaml");
    const std::vector<std::vector<std::string>> cases = {
        {stereoctlPath(), "calibrate", "--out", out},
        {stereoctlPath(), "calibrate", "--rectified", "--focal-px", "615", "--baseline-m", "0.1",
         "--out", out}, // no --size
        {stereoctlPath(), "calibrate", "--rectified", "--focal-px", "615", "--baseline-m", "0.1",
         "--size", "384by288", "--out", out},
        {stereoctlPath(), "calibrate", "--rectified", "--focal-px", "0", "--baseline-m", "0.1",
         "--size", "384x288", "--out", out},
        {stereoctlPath(), "calibrate", "--rectified", "--focal-px", "615", "--baseline-m", "0.1",
         "--size", "384x288"}, // no --out
        {stereoctlPath(), "calibrate", "--rectified", "--focal-px", "615", "--baseline-m", "0.1",
         "--size", "384x288", "--board", "9x6", "--out", out},
    };
    for (const auto& argv : cases) {
        const ProcessResult run = runProcess(argv);
        EXPECT_EQ(run.exit_code, 2) << argv.at(2) << " ... " << run.err;
        EXPECT_EQ(test::lineCount(run.err), 1u) << run.err;
    }
}

TEST(StereoctlHelp, NoSubcommandPrintsHelpAndExitsTwo)
{
    const ProcessResult run = runProcess({stereoctlPath()});
    EXPECT_EQ(run.exit_code, 2);
    for (const char* command : {"distance", "status", "watch", "snapshot", "depth", "calibrate"}) {
        EXPECT_NE(run.err.find(command), std::string::npos) << command;
    }
}

TEST(StereoctlHelp, EveryCommandHasHelp)
{
    const std::vector<std::pair<std::string, std::string>> commands = {
        {"distance", "--max-age-ms"}, {"status", "--json"},         {"watch", "--socket"},
        {"snapshot", "--colormap"},   {"depth", "--max-disparity"}, {"calibrate", "--rectified"}};
    for (const auto& [command, option] : commands) {
        const ProcessResult run = runProcess({stereoctlPath(), command, "--help"});
        EXPECT_EQ(run.exit_code, 0) << command;
        EXPECT_NE(run.out.find(option), std::string::npos) << command << ":\n" << run.out;
    }
    EXPECT_EQ(runProcess({stereoctlPath(), "--help"}).exit_code, 0);
}

TEST(StereoctlHelp, UnknownSubcommandExitsTwo)
{
    const ProcessResult run = runProcess({stereoctlPath(), "teleport"});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_EQ(test::lineCount(run.err), 1u) << run.err;
}

TEST(StereoctlUnreachable, EveryClientCommandExitsThreeNamingSocketAndReason)
{
    test::TempDir dir;
    const std::string socket = dir.file("absent.sock");
    const std::vector<std::vector<std::string>> cases = {
        {"distance"},
        {"distance", "--json"},
        {"status"},
        {"watch"},
        {"snapshot", "--depth", dir.file("d.png")}};
    for (const auto& command : cases) {
        std::vector<std::string> argv = {stereoctlPath()};
        argv.insert(argv.end(), command.begin(), command.end());
        argv.insert(argv.end(), {"--socket", socket});
        const ProcessResult run = runProcess(argv);
        EXPECT_EQ(run.exit_code, 3) << command.at(0) << ": " << run.err;
        EXPECT_NE(run.err.find(socket), std::string::npos) << run.err;
        EXPECT_NE(run.err.find("No such file or directory"), std::string::npos) << run.err;
        EXPECT_TRUE(run.out.empty()) << run.out;
    }
}

TEST(StereoctlUnreachable, SocketComesFromTheEnvironmentWhenNotGiven)
{
    test::TempDir dir;
    const std::string from_env = dir.file("env.sock");
    const std::string from_option = dir.file("option.sock");
    ProcessResult run = runProcess({stereoctlPath(), "distance"}, {"STEREOD_SOCKET=" + from_env});
    EXPECT_EQ(run.exit_code, 3);
    EXPECT_NE(run.err.find(from_env), std::string::npos) << run.err;

    run = runProcess({stereoctlPath(), "distance", "--socket", from_option},
                     {"STEREOD_SOCKET=" + from_env});
    EXPECT_EQ(run.exit_code, 3);
    EXPECT_NE(run.err.find(from_option), std::string::npos) << run.err;
}

// --socket before the command, as git, docker and systemctl users write global options:
// every command that talks to the service takes it there as well as after itself.
TEST(StereoctlUnreachable, SocketBeforeTheCommandIsTakenByEveryClientCommand)
{
    test::TempDir dir;
    const std::string socket = dir.file("before.sock");
    const std::vector<std::vector<std::string>> cases = {{"distance"},
                                                         {"distance", "--json"},
                                                         {"status"},
                                                         {"watch"},
                                                         {"snapshot", "--depth", dir.file("d.png")},
                                                         {"record", "--out", dir.file("recording")},
                                                         {"calibrate", "--live", "--count", "6",
                                                          "--board", "9x6", "--square-m", "0.025",
                                                          "--out", dir.file("rig.yaml")}};
    for (const auto& command : cases) {
        std::vector<std::string> argv = {stereoctlPath(), "--socket", socket};
        argv.insert(argv.end(), command.begin(), command.end());
        const ProcessResult run = runProcess(argv);
        EXPECT_EQ(run.exit_code, 3) << command.at(0) << ": " << run.err;
        EXPECT_NE(run.err.find(socket), std::string::npos) << command.at(0) << ": " << run.err;
    }
}

// The command's own --socket, then --socket before the command, then STEREOD_SOCKET.
TEST(StereoctlUnreachable, SocketAfterTheCommandWinsThenBeforeItThenTheEnvironment)
{
    test::TempDir dir;
    const std::string after = dir.file("after.sock");
    const std::string before = dir.file("before.sock");
    const std::string from_env = dir.file("env.sock");
    const std::string env = "STEREOD_SOCKET=" + from_env;

    ProcessResult run =
        runProcess({stereoctlPath(), "--socket", before, "distance", "--socket", after}, {env});
    EXPECT_EQ(run.exit_code, 3) << run.err;
    EXPECT_NE(run.err.find(after), std::string::npos) << run.err;

    run = runProcess({stereoctlPath(), "--socket", before, "status"}, {env});
    EXPECT_EQ(run.exit_code, 3) << run.err;
    EXPECT_NE(run.err.find(before), std::string::npos) << run.err;

    run = runProcess({stereoctlPath(), "status", "--socket", after}, {env});
    EXPECT_EQ(run.exit_code, 3) << run.err;
    EXPECT_NE(run.err.find(after), std::string::npos) << run.err;

    run = runProcess({stereoctlPath(), "status"}, {env});
    EXPECT_EQ(run.exit_code, 3) << run.err;
    EXPECT_NE(run.err.find(from_env), std::string::npos) << run.err;
}

// A command that does not talk to the service ignores --socket before it.
TEST(StereoctlUnreachable, OfflineCommandsIgnoreTheSocketBeforeThem)
{
    test::TempDir dir;
    const std::string out = dir.file("rig.yaml");
    const ProcessResult run = runProcess({stereoctlPath(), "--socket", dir.file("absent.sock"),
                                          "calibrate", "--rectified", "--focal-px", "615",
                                          "--baseline-m", "0.1", "--size", "384x288", "--out", out},
                                         {"STEREOD_SOCKET=" + dir.file("env.sock")});
    EXPECT_EQ(run.exit_code, 0) << run.err;
    EXPECT_TRUE(std::filesystem::exists(out));
}

TEST(StereoctlUnreachable, DefaultSocketIsTheServicesPath)
{
    const ProcessResult help = runProcess({stereoctlPath(), "distance", "--help"});
    EXPECT_NE(help.out.find("/run/stereod/stereod.sock"), std::string::npos) << help.out;
}

} // namespace
} // namespace stereod
