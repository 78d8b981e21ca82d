#pragma once
// A temporary directory that removes itself. Thread-bound (one per test).

#include <string>

namespace stereod::test {

// A fresh directory under $TMPDIR (or /tmp) that is removed with its contents on
// destruction. Kept short: Unix socket paths are limited to 107 bytes.
class TempDir {
  public:
    TempDir();
    ~TempDir();
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;

    const std::string& path() const noexcept { return path_; }
    std::string file(const std::string& name) const { return path_ + "/" + name; }
    // Writes `text` to `name` (relative, directories created); returns its path.
    std::string write(const std::string& name, const std::string& text) const;

  private:
    std::string path_;
};

} // namespace stereod::test
