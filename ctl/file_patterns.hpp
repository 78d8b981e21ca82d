#pragma once
// Shell-style file patterns on the command line (`--left 'left*.png'`).
//
// Reentrant.

#include <string>
#include <vector>

namespace stereod {

// The files `pattern` matches, sorted byte by byte (pairs are taken in this order on both
// sides). Throws UsageError naming `option` when nothing matches or a directory of the
// pattern cannot be read.
std::vector<std::string> expandGlob(const std::string& pattern, const char* option);

// The last component of a path, for reports ("left01.png").
std::string fileName(const std::string& path);

} // namespace stereod
