// ProtocolClient against a scripted peer on a real Unix socket: framing (lines split
// across writes, payloads right behind their line), error replies, and every way the
// connection can fail, each named with the socket path.

#include <cerrno>
#include <cstring>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "ctl/client.hpp"
#include "tests/support/process.hpp"
#include "tests/support/scripted_peer.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;
using Json = nlohmann::ordered_json;

using test::readRequestLine;
using test::ScriptedPeer;
using test::writeAll;

// The message of the E that `call` must throw; a test failure (and "") if it throws none.
template <typename E, typename Call> std::string messageOf(Call&& call)
{
    try {
        call();
    } catch (const E& e) {
        return e.what();
    }
    ADD_FAILURE() << "expected an exception";
    return {};
}

TEST(ProtocolClient, ReplyLinesSplitAcrossWritesAndPayloadsBehindThem)
{
    test::TempDir dir;
    const std::string path = dir.file("s.sock");
    std::string received;
    const std::vector<uint16_t> depth = {0, 1000, 65535, 873};
    {
        ScriptedPeer peer(path, [&](int fd) {
            received = readRequestLine(fd);
            // The reply line in two pieces, then the payload glued to the line's end.
            writeAll(fd, R"({"ok": true, "payloads": [{"name": "depth", )");
            std::this_thread::sleep_for(20ms);
            std::string rest = R"("bytes": 8}]})";
            rest += '\n';
            rest.append(reinterpret_cast<const char*>(depth.data()), 8);
            rest += R"({"event": "reading"})";
            rest += '\n';
            writeAll(fd, rest);
        });
        ProtocolClient client(path, 2000ms);
        Json reply = client.request({{"cmd", "snapshot"}, {"items", {"depth"}}});
        EXPECT_EQ(reply["payloads"][0]["bytes"], 8);
        std::vector<uint16_t> got(4);
        client.readPayload(got.data(), 8);
        EXPECT_EQ(got, depth);
        EXPECT_EQ(client.readJson()["event"], "reading");
    }
    EXPECT_EQ(Json::parse(received), Json({{"cmd", "snapshot"}, {"items", {"depth"}}}));
}

TEST(ProtocolClient, ErrorReplyBecomesServiceErrorWithItsCode)
{
    test::TempDir dir;
    const std::string path = dir.file("s.sock");
    ScriptedPeer peer(path, [](int fd) {
        readRequestLine(fd);
        writeAll(fd, "{\"ok\":false,\"error\":{\"code\":\"not_available\",\"message\":\"no frame "
                     "processed yet\"}}\n");
    });
    ProtocolClient client(path, 2000ms);
    try {
        client.request({{"cmd", "snapshot"}});
        ADD_FAILURE() << "an ok:false reply must throw";
    } catch (const ServiceError& e) {
        EXPECT_EQ(e.code(), "not_available");
        EXPECT_NE(std::string(e.what()).find("no frame processed yet"), std::string::npos);
    }
}

TEST(ProtocolClient, MissingSocketNamesThePathAndTheErrno)
{
    test::TempDir dir;
    const std::string path = dir.file("nobody-here.sock");
    int error_number = 0;
    const std::string message = messageOf<ClientError>([&] {
        try {
            ProtocolClient client(path, 500ms);
        } catch (const ClientError& e) {
            error_number = e.errorNumber();
            throw;
        }
    });
    EXPECT_EQ(error_number, ENOENT);
    EXPECT_NE(message.find(path), std::string::npos) << message;
    EXPECT_NE(message.find(std::strerror(ENOENT)), std::string::npos) << message;
}

TEST(ProtocolClient, SocketFileWithoutListenerIsRefused)
{
    test::TempDir dir;
    const std::string path = dir.file("dead.sock");
    {
        // Bound, then closed without unlinking: what a crashed service leaves behind.
        const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
        sockaddr_un address{};
        address.sun_family = AF_UNIX;
        std::strncpy(address.sun_path, path.c_str(), sizeof(address.sun_path) - 1);
        ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0);
        ::close(fd);
    }
    const std::string message = messageOf<ClientError>([&] { ProtocolClient client(path, 500ms); });
    EXPECT_NE(message.find(path), std::string::npos) << message;
    EXPECT_NE(message.find(std::strerror(ECONNREFUSED)), std::string::npos) << message;
}

TEST(ProtocolClient, PeerClosingMidReplyIsAClientError)
{
    test::TempDir dir;
    const std::string path = dir.file("s.sock");
    ScriptedPeer peer(path, [](int fd) {
        readRequestLine(fd);
        writeAll(fd, "{\"ok\":true,");
    });
    ProtocolClient client(path, 2000ms);
    const std::string message = messageOf<ClientError>([&] {
        client.request({{"cmd", "status"}});
    });
    EXPECT_NE(message.find("closed the connection"), std::string::npos) << message;
}

TEST(ProtocolClient, PayloadCutShortIsAClientError)
{
    test::TempDir dir;
    const std::string path = dir.file("s.sock");
    ScriptedPeer peer(path, [](int fd) { writeAll(fd, "{\"bytes\":100}\n0123456789"); });
    ProtocolClient client(path, 2000ms);
    EXPECT_EQ(client.readJson()["bytes"], 100);
    std::vector<char> payload(100);
    EXPECT_THROW(client.readPayload(payload.data(), payload.size()), ClientError);
}

TEST(ProtocolClient, LineThatIsNotJsonIsAClientError)
{
    test::TempDir dir;
    const std::string path = dir.file("s.sock");
    ScriptedPeer peer(path, [](int fd) { writeAll(fd, "HTTP/1.1 400 Bad Request\n"); });
    ProtocolClient client(path, 2000ms);
    const std::string message = messageOf<ClientError>([&] { client.readJson(); });
    EXPECT_NE(message.find("HTTP/1.1 400"), std::string::npos) << message;
}

TEST(ProtocolClient, SilentPeerTimesOut)
{
    test::TempDir dir;
    const std::string path = dir.file("s.sock");
    const int done = ::eventfd(0, EFD_CLOEXEC);
    {
        ScriptedPeer peer(path, [done](int) {
            // Holds the connection open, silent, until the client has given up.
            uint64_t value = 0;
            ASSERT_EQ(::read(done, &value, sizeof(value)), static_cast<ssize_t>(sizeof(value)));
        });
        {
            ProtocolClient client(path, 100ms);
            const std::string message = messageOf<ClientError>([&] {
                client.request({{"cmd", "status"}});
            });
            EXPECT_NE(message.find("timed out"), std::string::npos) << message;
            EXPECT_NE(message.find(path), std::string::npos) << message;
        }
        const uint64_t one = 1;
        ASSERT_EQ(::write(done, &one, sizeof(one)), static_cast<ssize_t>(sizeof(one)));
    }
    ::close(done);
}

TEST(ProtocolClient, CancelDescriptorEndsAWaitWithoutLimit)
{
    test::TempDir dir;
    const std::string path = dir.file("s.sock");
    const int cancel = ::eventfd(0, EFD_CLOEXEC);
    {
        ScriptedPeer peer(path, [](int fd) {
            writeAll(fd, "{\"ok\":true,\"stream\":\"readings\"}\n");
            // Stays connected and silent until the client hangs up.
            char c = 0;
            while (::read(fd, &c, 1) > 0) {
            }
        });
        ProtocolClient client(path, 2000ms);
        client.setCancelFd(cancel);
        client.setTimeout(ProtocolClient::kWaitForever);
        EXPECT_EQ(client.readJson()["stream"], "readings");
        const uint64_t one = 1;
        ASSERT_EQ(::write(cancel, &one, sizeof(one)), static_cast<ssize_t>(sizeof(one)));
        EXPECT_THROW(client.readJson(), ClientCancelled);
    }
    ::close(cancel);
}

} // namespace
} // namespace stereod
