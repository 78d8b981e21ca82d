#pragma once
// errno as text and as an exception, one way for every folder. std::strerror is not
// thread-safe; the system category's message is.

#include <string>
#include <system_error>

namespace stereod {

// "No such file or directory" for ENOENT.
std::string errnoText(int error);

// A std::system_error whose what() reads "<what>: <errno text>".
std::system_error systemError(int error, const std::string& what);

} // namespace stereod
