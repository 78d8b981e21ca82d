#pragma once
// The listening Unix socket of the service (socket.path): bound with the file's mode and
// group, or handed over by systemd (socket activation), and its file removed at the end if
// it is still the one bound.
//
// Thread contract: a ListeningSocket on one thread; removeOwnedSocketFile() from any
// thread.

#include <stdexcept>
#include <string>

#include <sys/types.h>

#include "base/unique_fd.hpp"
#include "config/service_config.hpp"

namespace stereod {

// The socket cannot be set up. what() names the path and the reason (errno text).
class SocketError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

class ListeningSocket {
  public:
    // Binds and listens, non-blocking: creates the parent directory when missing; refuses
    // a symbolic link or a non-socket at the path; removes a stale socket file only when
    // nothing answers on it, and fails when something does; applies socket.mode and
    // socket.group. With `accept_systemd_socket`, takes the socket systemd hands over for
    // socket.path instead, when there is one; its file then belongs to systemd and is left
    // in place. Throws SocketError naming the path and the reason.
    ListeningSocket(const SocketConfig& config, bool accept_systemd_socket);
    // Closes the socket and removes its file if it is still the one bound.
    ~ListeningSocket();

    ListeningSocket(const ListeningSocket&) = delete;
    ListeningSocket& operator=(const ListeningSocket&) = delete;

    int fd() const noexcept { return fd_.get(); }
    const std::string& path() const noexcept { return path_; }

  private:
    UniqueFd fd_;
    std::string path_;
    bool owns_file_ = false; // false for a socket handed over by systemd
    dev_t dev_ = 0;          // identity of the bound file, so that only it is removed
    ino_t ino_ = 0;
};

// Removes the socket file a ListeningSocket of this process bound and still owns, if any
// (never a file systemd handed over, nor one that replaced ours). Any thread: for a stop
// that cannot wait for the server's destructor (abandonProcess(), daemon/signal_watch.hpp).
void removeOwnedSocketFile() noexcept;

} // namespace stereod
