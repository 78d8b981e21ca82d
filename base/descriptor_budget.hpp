#pragma once
// Descriptors as a resource the service shares out: how many it may still open
// (RLIMIT_NOFILE's soft limit less those open now), and one descriptor held in spare for
// the moment there is none left, so that an accept loop can still take the connection
// waiting on its listening socket and close it instead of seeing EMFILE for ever (the
// listening socket stays readable while a connection waits: without the spare, a loop
// that waits for readability spins).
//
// Thread contract: countOpenDescriptors() and descriptorLimit() from any thread; a
// SpareDescriptor is thread-bound (the accept loop's thread).
// Units: descriptors.

#include <cerrno>
#include <cstddef>

#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>

#include "base/unique_fd.hpp"

namespace stereod {

// The descriptors this process has open now (from /proc/self/fd; 0 when unreadable).
std::size_t countOpenDescriptors() noexcept;

// RLIMIT_NOFILE's soft limit (what open() and accept() are held to).
std::size_t descriptorLimit() noexcept;

class SpareDescriptor {
  public:
    SpareDescriptor() noexcept { take(); }

    // After accept() failed with EMFILE or ENFILE: frees the spare, accepts the waiting
    // connection, hands it to `refuse` (which may send a last word), closes it, and takes
    // the spare again. Returns whether a connection was taken (false: none was waiting,
    // or not even the spare made room).
    template <typename Refuse> bool refuseWaitingConnection(int listening_fd, Refuse&& refuse)
    {
        // Only a connection that waits: accept() on a blocking socket must not block here.
        pollfd waiting{listening_fd, POLLIN, 0};
        if (::poll(&waiting, 1, 0) != 1 || (waiting.revents & POLLIN) == 0)
            return false;
        spare_.reset();
        UniqueFd connection(
            ::accept4(listening_fd, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC));
        const bool taken = connection.valid();
        if (taken)
            refuse(connection.get());
        connection.reset();
        take();
        return taken;
    }

    bool held() const noexcept { return spare_.valid(); }

  private:
    void take() noexcept { spare_.reset(::open("/dev/null", O_RDONLY | O_CLOEXEC)); }

    UniqueFd spare_;
};

// True for the errno of an accept() that failed for want of descriptors.
inline bool outOfDescriptors(int error) noexcept
{
    return error == EMFILE || error == ENFILE;
}

} // namespace stereod
