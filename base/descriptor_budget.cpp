#include "base/descriptor_budget.hpp"

#include <dirent.h>
#include <sys/resource.h>

namespace stereod {

std::size_t countOpenDescriptors() noexcept
{
    DIR* dir = ::opendir("/proc/self/fd");
    if (dir == nullptr)
        return 0;
    std::size_t count = 0;
    while (const dirent* entry = ::readdir(dir))
        count += entry->d_name[0] != '.' ? 1 : 0;
    ::closedir(dir);
    return count > 0 ? count - 1 : 0; // the directory's own descriptor
}

std::size_t descriptorLimit() noexcept
{
    rlimit limit{};
    if (::getrlimit(RLIMIT_NOFILE, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY)
        return static_cast<std::size_t>(-1);
    return static_cast<std::size_t>(limit.rlim_cur);
}

} // namespace stereod
