#include "daemon/peer_credentials.hpp"

#include <algorithm>
#include <cerrno>

#include <sys/socket.h>

namespace stereod {

bool readPeerCredentials(int fd, bool with_groups, PeerCredentials& peer)
{
    ucred credentials{};
    socklen_t length = sizeof credentials;
    if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &credentials, &length) != 0)
        return false;
    peer.pid = credentials.pid;
    peer.uid = credentials.uid;
    peer.gid = credentials.gid;
    if (!with_groups)
        return true;
    peer.groups.resize(32);
    for (int attempt = 0; attempt < 2; ++attempt) {
        auto bytes = static_cast<socklen_t>(peer.groups.size() * sizeof(gid_t));
        if (::getsockopt(fd, SOL_SOCKET, SO_PEERGROUPS, peer.groups.data(), &bytes) == 0) {
            peer.groups.resize(bytes / sizeof(gid_t));
            return true;
        }
        if (errno != ERANGE)
            break;
        peer.groups.resize(bytes / sizeof(gid_t)); // the kernel said how many there are
    }
    peer.groups.clear(); // an old kernel: only the primary group counts
    return true;
}

bool peerAllowed(const SocketConfig& config, const PeerCredentials& peer)
{
    if (config.allow_uids.empty() && config.allow_gids.empty())
        return true;
    const auto listed = [](const std::vector<uint32_t>& ids, uint32_t id) {
        return std::find(ids.begin(), ids.end(), id) != ids.end();
    };
    if (listed(config.allow_uids, peer.uid) || listed(config.allow_gids, peer.gid))
        return true;
    return std::any_of(peer.groups.begin(), peer.groups.end(),
                       [&](gid_t group) { return listed(config.allow_gids, group); });
}

} // namespace stereod
