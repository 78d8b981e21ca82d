// The listening socket: bound with its mode, its file removed when it goes (and only if it
// is still the file it bound), and the paths it refuses.

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <sys/stat.h>

#include "daemon/listening_socket.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::TempDir;

class ListeningSocketTest : public ::testing::Test {
  protected:
    SocketConfig config(const std::string& name = "run/stereod.sock") const
    {
        SocketConfig socket;
        socket.path = dir_.file(name);
        socket.mode = 0600;
        return socket;
    }

    static bool isSocket(const std::string& path)
    {
        struct stat info {};
        return ::lstat(path.c_str(), &info) == 0 && S_ISSOCK(info.st_mode);
    }

    // The problem a ListeningSocket on `socket` is refused with; empty when it is not.
    static std::string refusal(const SocketConfig& socket)
    {
        try {
            ListeningSocket listening(socket, false);
        } catch (const SocketError& e) {
            return e.what();
        }
        return {};
    }

    TempDir dir_;
};

TEST_F(ListeningSocketTest, BindsWithItsModeAndRemovesItsFile)
{
    const SocketConfig socket = config();
    {
        ListeningSocket listening(socket, false);
        EXPECT_GE(listening.fd(), 0);
        struct stat info {};
        ASSERT_EQ(::lstat(socket.path.c_str(), &info), 0);
        EXPECT_TRUE(S_ISSOCK(info.st_mode));
        EXPECT_EQ(info.st_mode & 0777, 0600u);
    }
    EXPECT_FALSE(std::filesystem::exists(socket.path));
}

TEST_F(ListeningSocketTest, LeavesAFileThatReplacedItsOwn)
{
    const SocketConfig socket = config();
    {
        ListeningSocket listening(socket, false);
        std::filesystem::remove(socket.path);
        std::ofstream(socket.path) << "someone else's";
    }
    EXPECT_TRUE(std::filesystem::is_regular_file(socket.path));
}

TEST_F(ListeningSocketTest, RemoveOwnedSocketFileRemovesItOnce)
{
    const SocketConfig socket = config();
    ListeningSocket listening(socket, false);
    removeOwnedSocketFile();
    EXPECT_FALSE(std::filesystem::exists(socket.path));
    // A new file at the path is not ours.
    std::ofstream(socket.path) << "new";
    removeOwnedSocketFile();
    EXPECT_TRUE(std::filesystem::exists(socket.path));
}

TEST_F(ListeningSocketTest, RefusesWhatIsNotAStaleSocket)
{
    SocketConfig socket = config("taken.sock");
    std::ofstream(socket.path) << "precious";
    EXPECT_NE(refusal(socket).find("something other than a socket"), std::string::npos);

    socket = config("link.sock");
    std::filesystem::create_symlink(dir_.file("elsewhere.sock"), socket.path);
    EXPECT_NE(refusal(socket).find("symbolic link"), std::string::npos);

    socket = config(std::string(120, 's'));
    EXPECT_NE(refusal(socket).find("too long"), std::string::npos);

    const SocketConfig live = config("live.sock");
    ListeningSocket listening(live, false);
    EXPECT_NE(refusal(live).find("another service is listening"), std::string::npos);
    EXPECT_TRUE(isSocket(live.path));
}

} // namespace
} // namespace stereod
