#include "tests/support/dds_domain.hpp"

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

namespace stereod::test {
namespace {

// RTPS maps domain d to UDP ports from 7400 + 250 d. Up to domain 100 they stay below
// Linux's ephemeral ports (32768 and up), which the other tests' sockets take at random:
// a participant that found its port taken could miss its peers. Domain 0 is left to
// anything else on the machine.
constexpr uint32_t kFirstDomain = 1;
constexpr uint32_t kLastDomain = 100;

// Fixed, not $TMPDIR: every test process must see the same lock files.
std::string lockPath(uint32_t id)
{
    return "/tmp/stereod-test-dds-domain-" + std::to_string(id) + ".lock";
}

} // namespace

DdsDomainLease::DdsDomainLease()
{
    constexpr uint32_t kCount = kLastDomain - kFirstDomain + 1;
    // Starting from the pid spreads the search; the lock decides.
    const auto start = static_cast<uint32_t>(::getpid()) % kCount;
    for (uint32_t i = 0; i < kCount; ++i) {
        const uint32_t id = kFirstDomain + (start + i) % kCount;
        const int fd = ::open(lockPath(id).c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
        if (fd < 0)
            continue;
        if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
            id_ = id;
            lock_fd_ = fd;
            return;
        }
        ::close(fd);
    }
    throw std::runtime_error("no free DDS domain id for the test: all of " +
                             std::to_string(kFirstDomain) + ".." + std::to_string(kLastDomain) +
                             " are locked under /tmp/stereod-test-dds-domain-*.lock");
}

DdsDomainLease::~DdsDomainLease()
{
    if (lock_fd_ >= 0)
        ::close(lock_fd_);
}

} // namespace stereod::test
