#pragma once
// A DDS domain id that no other test process holds while this one runs. Tests run in
// parallel, and two services or peers in one domain on the loopback interface find each
// other: a test's publisher would feed another test's service. A domain id is taken by an
// exclusive lock on a file named after it, so the kernel, not a hash of the pid, keeps
// concurrent tests apart; the lock goes with the lease (or with the process).

#include <cstdint>
#include <string>

namespace stereod::test {

class DdsDomainLease {
  public:
    // Throws std::runtime_error when every domain id is held.
    DdsDomainLease();
    ~DdsDomainLease();
    DdsDomainLease(const DdsDomainLease&) = delete;
    DdsDomainLease& operator=(const DdsDomainLease&) = delete;

    uint32_t id() const noexcept { return id_; }
    std::string text() const { return std::to_string(id_); }

  private:
    uint32_t id_ = 0;
    int lock_fd_ = -1;
};

} // namespace stereod::test
