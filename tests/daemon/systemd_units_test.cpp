// The systemd integration as `cmake --install` lays it out: installed into a temporary
// prefix, the units pass `systemd-analyze verify` and the offline security review, the
// sysusers.d entry creates the user (in a scratch root), the tmpfiles.d entry is valid,
// and the units agree with the service (binary path, socket path).
//
// Runs without systemd as PID 1: verify and `security --offline` only read unit files
// and the host's unit directories (systemd's own targets); sysusers and tmpfiles work on
// a scratch root with --root. What cannot be checked here: that the sandbox holds at run
// time (seccomp filter, device policy, namespaces) - docs/service.md says how it was.

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include "config/service_config.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::ProcessResult;
using test::runProcess;
using test::TempDir;

// A program on PATH (or in the usual system directories), or "" when there is none.
std::string findProgram(const std::string& name)
{
    std::string path = std::getenv("PATH") != nullptr ? std::getenv("PATH") : "";
    path += ":/usr/local/bin:/usr/bin:/bin:/usr/sbin:/sbin";
    std::istringstream dirs(path);
    for (std::string dir; std::getline(dirs, dir, ':');) {
        const std::string candidate = dir + "/" + name;
        if (!dir.empty() && ::access(candidate.c_str(), X_OK) == 0)
            return candidate;
    }
    return "";
}

std::string readFile(const std::string& path)
{
    std::ifstream file(path);
    return std::string(std::istreambuf_iterator<char>(file), {});
}

// The value of `key=` in a unit or entry file (the first one), or "".
std::string unitValue(const std::string& text, const std::string& key)
{
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);) {
        if (line.rfind(key + "=", 0) == 0)
            return line.substr(key.size() + 1);
    }
    return "";
}

class SystemdUnits : public ::testing::Test {
  protected:
    static void SetUpTestSuite()
    {
        for (const char* dir :
             {STEREOD_SYSTEMD_UNIT_DIR, STEREOD_SYSUSERS_DIR, STEREOD_TMPFILES_DIR}) {
            if (std::filesystem::path(dir).is_absolute())
                return; // SetUp() skips: an absolute directory cannot go into a temporary prefix
        }
        prefix_ = new TempDir();
        for (const char* component : {"Unspecified", "systemd"}) {
            const ProcessResult installed =
                runProcess({STEREOD_CMAKE_COMMAND, "--install", STEREOD_BINARY_DIR, "--prefix",
                            prefix_->path(), "--component", component});
            install_log_ += installed.out + installed.err;
            install_ok_ = install_ok_ && installed.exit_code == 0;
        }
    }

    static void TearDownTestSuite()
    {
        delete prefix_;
        prefix_ = nullptr;
    }

    void SetUp() override
    {
        if (prefix_ == nullptr)
            GTEST_SKIP() << "the systemd directories are configured absolute ("
                         << STEREOD_SYSTEMD_UNIT_DIR << ", " << STEREOD_SYSUSERS_DIR << ", "
                         << STEREOD_TMPFILES_DIR << "): they cannot be installed into a "
                         << "temporary prefix";
        ASSERT_TRUE(install_ok_) << install_log_;
    }

    // systemd's tools are part of the setup (scripts/setup.sh): missing is a failure.
    static std::string tool(const std::string& name)
    {
        const std::string found = findProgram(name);
        EXPECT_FALSE(found.empty()) << name << " not found: scripts/setup.sh installs systemd";
        return found;
    }

    static std::string installed(const std::string& relative)
    {
        return prefix_->path() + "/" + relative;
    }
    static std::string unitPath(const std::string& name)
    {
        return installed(std::string(STEREOD_SYSTEMD_UNIT_DIR) + "/" + name);
    }

    static TempDir* prefix_;
    static bool install_ok_;
    static std::string install_log_;
};

TempDir* SystemdUnits::prefix_ = nullptr;
bool SystemdUnits::install_ok_ = true;
std::string SystemdUnits::install_log_;

TEST_F(SystemdUnits, InstallPutsEverythingWhereTheDistributionExpectsIt)
{
    for (const std::string& file : {unitPath("stereod.service"), unitPath("stereod.socket"),
                                    installed(std::string(STEREOD_SYSUSERS_DIR) + "/stereod.conf"),
                                    installed(std::string(STEREOD_TMPFILES_DIR) + "/stereod.conf"),
                                    installed("share/stereod/stereod.yaml"),
                                    installed("bin/stereod"), installed("bin/stereoctl")})
        EXPECT_TRUE(std::filesystem::is_regular_file(file)) << file << "\n" << install_log_;
}

TEST_F(SystemdUnits, VerifyIsClean)
{
    const std::string analyze = tool("systemd-analyze");
    ASSERT_FALSE(analyze.empty());
    const ProcessResult verified =
        runProcess({analyze, "verify", unitPath("stereod.service"), unitPath("stereod.socket")});
    EXPECT_EQ(verified.exit_code, 0) << verified.out << verified.err;
    // Clean means no warning either (an unknown key is only a warning).
    EXPECT_EQ(verified.err, "");
    EXPECT_EQ(verified.out, "");
}

TEST_F(SystemdUnits, SandboxRatesAsLowExposure)
{
    const std::string analyze = tool("systemd-analyze");
    ASSERT_FALSE(analyze.empty());
    // Exposure on systemd's 0..10 scale, times ten: at most 2.0 ("OK" is below 3.0).
    const ProcessResult review = runProcess(
        {analyze, "security", "--offline=yes", "--threshold=20", unitPath("stereod.service")});
    EXPECT_EQ(review.exit_code, 0) << review.out << review.err;
    EXPECT_NE(review.out.find("Overall exposure level for stereod.service"), std::string::npos)
        << review.out << review.err;
}

TEST_F(SystemdUnits, UnitsAgreeWithTheService)
{
    const std::string service = readFile(unitPath("stereod.service"));
    const std::string socket = readFile(unitPath("stereod.socket"));
    EXPECT_EQ(unitValue(service, "Type"), "notify");
    EXPECT_EQ(unitValue(service, "NotifyAccess"), "main");
    EXPECT_EQ(unitValue(service, "Restart"), "on-failure");
    EXPECT_FALSE(unitValue(service, "WatchdogSec").empty());

    // ExecStart names the installed binary and the configuration directory's file.
    const std::string exec_start = unitValue(service, "ExecStart");
    EXPECT_EQ(exec_start, installed("bin/stereod") + " --config /etc/stereod/stereod.yaml");
    EXPECT_EQ(unitValue(service, "ConfigurationDirectory"), "stereod");
    EXPECT_EQ(unitValue(service, "RuntimeDirectory"), "stereod");

    // The socket unit listens where the service binds by default, with its mode: a
    // socket handed over by systemd is used only for the configured path.
    const ServiceConfig defaults = defaultConfig();
    EXPECT_EQ(unitValue(socket, "ListenStream"), defaults.socket.path);
    std::ostringstream mode;
    mode << '0' << std::oct << defaults.socket.mode;
    EXPECT_EQ(unitValue(socket, "SocketMode"), mode.str());
    EXPECT_EQ("/run/" + unitValue(service, "RuntimeDirectory") + "/stereod.sock",
              defaults.socket.path);
}

TEST_F(SystemdUnits, SysusersCreatesTheUserWithTheVideoGroup)
{
    const std::string sysusers = tool("systemd-sysusers");
    ASSERT_FALSE(sysusers.empty());
    TempDir root;
    std::filesystem::create_directory(root.file("etc"));
    const ProcessResult created =
        runProcess({sysusers, "--root=" + root.path(),
                    installed(std::string(STEREOD_SYSUSERS_DIR) + "/stereod.conf")});
    ASSERT_EQ(created.exit_code, 0) << created.out << created.err;
    // "name:x:..." lines; the video group lists stereod among its members.
    const std::string passwd = readFile(root.file("etc/passwd"));
    const std::string group = readFile(root.file("etc/group"));
    EXPECT_NE(("\n" + passwd).find("\nstereod:x:"), std::string::npos) << passwd;
    EXPECT_NE(("\n" + group).find("\nstereod:x:"), std::string::npos) << group;
    const std::size_t video = ("\n" + group).find("\nvideo:x:");
    ASSERT_NE(video, std::string::npos) << group;
    const std::string video_line = group.substr(video, group.find('\n', video) - video);
    const std::string members = video_line.substr(video_line.rfind(':') + 1);
    EXPECT_NE(("," + members + ",").find(",stereod,"), std::string::npos) << video_line;

    // The tmpfiles.d entry parses and applies in that root (the user now exists there),
    // and the example it copies to /etc/stereod is installed.
    const std::string tmpfiles = tool("systemd-tmpfiles");
    ASSERT_FALSE(tmpfiles.empty());
    const std::string entry = installed(std::string(STEREOD_TMPFILES_DIR) + "/stereod.conf");
    const ProcessResult applied =
        runProcess({tmpfiles, "--root=" + root.path(), "--create", entry});
    EXPECT_TRUE(std::filesystem::is_directory(root.file("run/stereod"))) << applied.err;
    const std::string copy_entry = "C /etc/stereod/stereod.yaml - - - - ";
    const std::string entries = readFile(entry);
    const std::size_t copy = entries.find(copy_entry);
    ASSERT_NE(copy, std::string::npos) << entries;
    const std::size_t from = copy + copy_entry.size();
    const std::string example = entries.substr(from, entries.find('\n', from) - from);
    EXPECT_TRUE(std::filesystem::is_regular_file(example)) << example;
}

} // namespace
} // namespace stereod
