#include "ctl/file_patterns.hpp"

#include <algorithm>

#include <fmt/format.h>
#include <glob.h>

#include "ctl/commands.hpp"

namespace stereod {

std::vector<std::string> expandGlob(const std::string& pattern, const char* option)
{
    glob_t matches{};
    const int status = ::glob(pattern.c_str(), GLOB_ERR, nullptr, &matches);
    std::vector<std::string> paths;
    if (status == 0) {
        for (size_t i = 0; i < matches.gl_pathc; ++i) {
            paths.emplace_back(matches.gl_pathv[i]);
        }
    }
    ::globfree(&matches);
    if (status == GLOB_NOMATCH) {
        throw UsageError(fmt::format("{} '{}' matches no file", option, pattern));
    }
    if (status != 0) {
        throw UsageError(
            fmt::format("{} '{}': cannot read a directory of the pattern", option, pattern));
    }
    std::sort(paths.begin(), paths.end());
    return paths;
}

std::string fileName(const std::string& path)
{
    const std::size_t slash = path.rfind('/');
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

} // namespace stereod
