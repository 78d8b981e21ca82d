#pragma once
// The process out of file descriptors, for the tests of what the service does then:
// RLIMIT_NOFILE lowered to a few above those open, and the rest taken (opened on
// /dev/null) until open() fails with EMFILE. release() (or the destructor) closes them and
// restores the limit.
//
// Thread-bound; it changes the whole process's limit, so the code under test on other
// threads meets EMFILE too, which is the point.

#include <utility>
#include <vector>

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include "base/descriptor_budget.hpp"
#include "base/unique_fd.hpp"

namespace stereod::test {

// True in the AddressSanitizer + UndefinedBehaviorSanitizer tree. UBSan's vptr check
// tests whether a vtable pointer is readable by writing it into a pipe of its own; with
// no descriptor left the pipe fails and every virtual call it checks is reported as "does
// not point to an object" (seen on std::error_category and std::thread's state). The
// tests that exhaust the process's descriptors skip there and run in the other trees
// (the normal one and ThreadSanitizer's).
constexpr bool sanitizersNeedDescriptors()
{
#if defined(__SANITIZE_ADDRESS__)
    return true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
    return true;
#else
    return false;
#endif
#else
    return false;
#endif
}

class DescriptorExhaustion {
  public:
    DescriptorExhaustion()
    {
        if (::getrlimit(RLIMIT_NOFILE, &saved_) != 0) {
            ADD_FAILURE() << "getrlimit(RLIMIT_NOFILE) failed";
            return;
        }
        rlimit lowered = saved_;
        lowered.rlim_cur = static_cast<rlim_t>(countOpenDescriptors() + 8);
        if (::setrlimit(RLIMIT_NOFILE, &lowered) != 0) {
            ADD_FAILURE() << "setrlimit(RLIMIT_NOFILE) failed";
            return;
        }
        lowered_ = true;
        for (UniqueFd fd; (fd = UniqueFd(::open("/dev/null", O_RDONLY | O_CLOEXEC)));)
            taken_.push_back(std::move(fd));
    }
    ~DescriptorExhaustion() { release(); }
    DescriptorExhaustion(const DescriptorExhaustion&) = delete;
    DescriptorExhaustion& operator=(const DescriptorExhaustion&) = delete;

    void release()
    {
        taken_.clear();
        if (lowered_ && ::setrlimit(RLIMIT_NOFILE, &saved_) != 0)
            ADD_FAILURE() << "RLIMIT_NOFILE not restored";
        lowered_ = false;
    }

  private:
    rlimit saved_{};
    bool lowered_ = false;
    std::vector<UniqueFd> taken_;
};

} // namespace stereod::test
