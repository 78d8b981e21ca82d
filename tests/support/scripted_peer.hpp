#pragma once
// A scripted peer on a real Unix socket, for the tests of stereoctl's side of the protocol:
// a listening socket whose one connection is served by a script on its own thread, and the
// byte-level helpers such scripts use.
//
// Thread contract: a ScriptedPeer is made and destroyed by the test's thread; the script
// runs on the peer's own thread and owns the connection's fd until it returns. The
// destructor waits for the script to end.

#include <cerrno>
#include <cstring>
#include <functional>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

namespace stereod::test {

// A listening socket whose one connection is served by `script` on its own thread.
class ScriptedPeer {
  public:
    ScriptedPeer(const std::string& path, std::function<void(int fd)> script)
    {
        listen_fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
        sockaddr_un address{};
        address.sun_family = AF_UNIX;
        std::strncpy(address.sun_path, path.c_str(), sizeof(address.sun_path) - 1);
        EXPECT_EQ(::bind(listen_fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0)
            << std::strerror(errno);
        EXPECT_EQ(::listen(listen_fd_, 4), 0);
        thread_ = std::thread([this, script = std::move(script)] {
            const int fd = ::accept(listen_fd_, nullptr, nullptr);
            if (fd >= 0) {
                script(fd);
                ::close(fd);
            }
        });
    }
    ~ScriptedPeer()
    {
        thread_.join();
        ::close(listen_fd_);
    }
    ScriptedPeer(const ScriptedPeer&) = delete;
    ScriptedPeer& operator=(const ScriptedPeer&) = delete;

  private:
    int listen_fd_ = -1;
    std::thread thread_;
};

inline void writeAll(int fd, const std::string& bytes)
{
    std::size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
        ASSERT_GT(n, 0) << std::strerror(errno);
        done += static_cast<std::size_t>(n);
    }
}

// Reads up to and including the first newline; the line without it.
inline std::string readRequestLine(int fd)
{
    std::string line;
    char c = 0;
    while (::read(fd, &c, 1) == 1 && c != '\n') {
        line.push_back(c);
    }
    return line;
}

} // namespace stereod::test
