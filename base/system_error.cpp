#include "base/system_error.hpp"

namespace stereod {

std::string errnoText(int error)
{
    return std::system_category().message(error);
}

std::system_error systemError(int error, const std::string& what)
{
    return std::system_error(error, std::system_category(), what);
}

} // namespace stereod
