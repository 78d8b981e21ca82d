// A preloaded library that makes the disk look full for one directory: write() to a file
// under $STEREOD_TEST_FULL_DIR fails with ENOSPC once $STEREOD_TEST_FULL_BYTES bytes have
// been written there by this process (a write that crosses the limit is cut short, as on
// a file system that runs out of blocks). Everything else passes through to libc.
//
// Used by the recorder's disk-full test: it needs no privileges (no tmpfs mount, no user
// namespace), so it runs the same on a developer machine and in a CI container.

#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <dlfcn.h>
#include <unistd.h>

namespace {

using WriteFunction = ssize_t (*)(int, const void*, size_t);

WriteFunction realWrite()
{
    static const auto real = reinterpret_cast<WriteFunction>(dlsym(RTLD_NEXT, "write"));
    return real;
}

std::atomic<long long> g_written{0};

// Whether `fd` is a file under the full directory.
bool underFullDirectory(int fd)
{
    const char* dir = std::getenv("STEREOD_TEST_FULL_DIR");
    if (dir == nullptr || dir[0] == '\0')
        return false;
    char link[64];
    std::snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    char target[PATH_MAX];
    const ssize_t length = ::readlink(link, target, sizeof target - 1);
    if (length <= 0)
        return false;
    target[length] = '\0';
    const std::size_t dir_length = std::strlen(dir);
    return std::strncmp(target, dir, dir_length) == 0 &&
           (target[dir_length] == '/' || target[dir_length] == '\0');
}

} // namespace

extern "C" ssize_t write(int fd, const void* data, size_t size)
{
    if (size > 0 && underFullDirectory(fd)) {
        const char* limit_text = std::getenv("STEREOD_TEST_FULL_BYTES");
        const long long limit = limit_text != nullptr ? std::atoll(limit_text) : 0;
        const long long before = g_written.load();
        if (before >= limit) {
            errno = ENOSPC;
            return -1;
        }
        const long long room = limit - before;
        const size_t allowed =
            static_cast<long long>(size) > room ? static_cast<size_t>(room) : size;
        const ssize_t written = realWrite()(fd, data, allowed);
        if (written > 0)
            g_written.fetch_add(written);
        return written;
    }
    return realWrite()(fd, data, size);
}
