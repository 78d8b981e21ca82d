// Who is at the other end of a connection, and the allow lists' rule: a user listed, or a
// primary or supplementary group listed, or no list at all.

#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

#include "daemon/peer_credentials.hpp"

namespace stereod {
namespace {

PeerCredentials peer(uid_t uid, gid_t gid, std::vector<gid_t> groups = {})
{
    PeerCredentials credentials;
    credentials.uid = uid;
    credentials.gid = gid;
    credentials.groups = std::move(groups);
    return credentials;
}

TEST(PeerCredentials, NoListLetsEveryoneIn)
{
    EXPECT_TRUE(peerAllowed(SocketConfig{}, peer(1000, 1000)));
}

TEST(PeerCredentials, AListedUserOrGroupIsLetIn)
{
    SocketConfig config;
    config.allow_uids = {1000};
    config.allow_gids = {44};
    EXPECT_TRUE(peerAllowed(config, peer(1000, 1000)));
    EXPECT_TRUE(peerAllowed(config, peer(1001, 44)));
    EXPECT_TRUE(peerAllowed(config, peer(1001, 1001, {20, 44})));
    EXPECT_FALSE(peerAllowed(config, peer(1001, 1001, {20})));
    EXPECT_FALSE(peerAllowed(config, peer(0, 0)));
}

TEST(PeerCredentials, TheKernelSaysWhoIsConnected)
{
    int fds[2] = {-1, -1};
    ASSERT_EQ(::socketpair(AF_UNIX, SOCK_STREAM, 0, fds), 0);
    PeerCredentials credentials;
    EXPECT_TRUE(readPeerCredentials(fds[0], /*with_groups=*/true, credentials));
    EXPECT_EQ(credentials.pid, ::getpid());
    EXPECT_EQ(credentials.uid, ::geteuid());
    EXPECT_EQ(credentials.gid, ::getegid());
    ::close(fds[0]);
    ::close(fds[1]);
}

TEST(PeerCredentials, NotASocketIsNoPeer)
{
    int pipe_fds[2] = {-1, -1};
    ASSERT_EQ(::pipe(pipe_fds), 0);
    PeerCredentials credentials;
    EXPECT_FALSE(readPeerCredentials(pipe_fds[0], false, credentials));
    ::close(pipe_fds[0]);
    ::close(pipe_fds[1]);
}

} // namespace
} // namespace stereod
