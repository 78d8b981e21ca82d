#pragma once
// Who is at the other end of a connection to the service's socket, as the kernel says, and
// whether socket.allow_uids / socket.allow_gids let it in.
//
// Reentrant: no state.

#include <cstdint>
#include <vector>

#include <sys/types.h>

#include "config/service_config.hpp"

namespace stereod {

// SO_PEERCRED gives the process, user and group at connect time, SO_PEERGROUPS its
// supplementary groups.
struct PeerCredentials {
    pid_t pid = 0;
    uid_t uid = static_cast<uid_t>(-1);
    gid_t gid = static_cast<gid_t>(-1);
    std::vector<gid_t> groups; // supplementary groups; read only when allow_gids needs them
};

// Reads the credentials of the peer of the connected socket `fd`, with its supplementary
// groups when `with_groups` (an old kernel without SO_PEERGROUPS gives none). False (errno
// set) when the kernel cannot say who it is.
bool readPeerCredentials(int fd, bool with_groups, PeerCredentials& peer);

// Whether socket.allow_uids / socket.allow_gids let this peer in (both empty: anyone who
// can open the socket file). Pure.
bool peerAllowed(const SocketConfig& config, const PeerCredentials& peer);

} // namespace stereod
