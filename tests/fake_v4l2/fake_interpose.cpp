// The libc entry points the fake defines in front of libc: each one serves fake devices
// and hands everything else to the next definition (libc, or a sanitizer interceptor).

#include <atomic>
#include <cerrno>
#include <cstdarg>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <unordered_map>

#include <dirent.h>
#include <dlfcn.h>
#include <fcntl.h>
#include <limits.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include "tests/fake_v4l2/fake_internal.hpp"

namespace stereod::fake {
namespace {

template <typename F> F next(const char* name)
{
    void* symbol = dlsym(RTLD_NEXT, name);
    if (symbol == nullptr)
        abort();
    return reinterpret_cast<F>(symbol);
}

// The real function behind an interposed one, looked up once. An atomic, not a function
// static: the guard of a function static lives in libstdc++, which ThreadSanitizer does
// not see in every build, and two capture threads reach the first poll() together.
template <typename F> F cachedNext(std::atomic<F>& cache, const char* name)
{
    F function = cache.load(std::memory_order_acquire);
    if (function == nullptr) {
        function = next<F>(name);
        cache.store(function, std::memory_order_release);
    }
    return function;
}

#define STEREOD_REAL(name, type)                                                                   \
    static std::atomic<type> real_##name##_cache{nullptr};                                         \
    const type real_##name = cachedNext(real_##name##_cache, #name)

using OpenFn = int (*)(const char*, int, ...);
using OpenatFn = int (*)(int, const char*, int, ...);
using CloseFn = int (*)(int);
using IoctlFn = int (*)(int, unsigned long, ...);
using MmapFn = void* (*)(void*, size_t, int, int, int, off_t);
using MunmapFn = int (*)(void*, size_t);
using ReadFn = ssize_t (*)(int, void*, size_t);
using WriteFn = ssize_t (*)(int, const void*, size_t);
using PollFn = int (*)(pollfd*, nfds_t, int);
using PpollFn = int (*)(pollfd*, nfds_t, const timespec*, const sigset_t*);
using SyscallFn = long (*)(long, ...);
using StatFn = int (*)(const char*, struct stat*);
using FstatFn = int (*)(int, struct stat*);
using FstatatFn = int (*)(int, const char*, struct stat*, int);
using AccessFn = int (*)(const char*, int);
using ReadlinkFn = ssize_t (*)(const char*, char*, size_t);
using RealpathFn = char* (*)(const char*, char*);
using OpendirFn = DIR* (*)(const char*);
using FdopendirFn = DIR* (*)(int);
using ReaddirFn = dirent* (*)(DIR*);
using Readdir64Fn = dirent64* (*)(DIR*);
using ClosedirFn = int (*)(DIR*);

// Whether an interposed call should look at fake devices at all.
bool active()
{
    if (Passthrough::active())
        return false;
    ensureLoadedFromEnvironment();
    return anyLoaded();
}

int fail(int error)
{
    errno = error;
    return -1;
}

// ---- directories that list fake entries ---------------------------------------------

struct FakeDir {
    std::vector<DirEntry> entries;
    size_t next = 0;
    dirent64 entry{};
};

std::mutex& dirMutex()
{
    static std::mutex* m = new std::mutex;
    return *m;
}
std::unordered_map<int, std::string>& dirFds()
{
    static auto* m = new std::unordered_map<int, std::string>;
    return *m;
}
std::unordered_map<DIR*, FakeDir>& dirs()
{
    static auto* m = new std::unordered_map<DIR*, FakeDir>;
    return *m;
}

bool listsFakeEntries(const std::string& path)
{
    return isFakeDirectory(path) || !fakeEntriesOf(path).empty();
}

void trackDir(DIR* dir, const std::string& path)
{
    if (dir == nullptr)
        return;
    std::lock_guard lock(dirMutex());
    dirs()[dir] = FakeDir{fakeEntriesOf(path), 0, {}};
}

dirent64* nextFakeEntry(DIR* dir)
{
    std::lock_guard lock(dirMutex());
    const auto it = dirs().find(dir);
    if (it == dirs().end() || it->second.next >= it->second.entries.size())
        return nullptr;
    FakeDir& fake = it->second;
    const DirEntry& e = fake.entries[fake.next++];
    std::memset(&fake.entry, 0, sizeof fake.entry);
    fake.entry.d_ino = 1'000'000 + fake.next;
    fake.entry.d_reclen = sizeof fake.entry;
    fake.entry.d_type = e.symlink ? DT_LNK : DT_CHR;
    std::strncpy(fake.entry.d_name, e.name.c_str(), sizeof fake.entry.d_name - 1);
    return &fake.entry;
}

// ---- open / close --------------------------------------------------------------------

int openPath(int dirfd, const char* path, int flags, mode_t mode)
{
    STEREOD_REAL(openat, OpenatFn);
    if (path != nullptr && active() && (path[0] == '/' || dirfd == AT_FDCWD)) {
        const std::string p = path[0] == '/' ? path : std::filesystem::absolute(path).string();
        if (const std::shared_ptr<Device> device = findDeviceByPath(p.c_str())) {
            const int rc = openDevice(device, flags);
            return rc < 0 ? fail(-rc) : rc;
        }
        if ((flags & O_DIRECTORY) != 0 && listsFakeEntries(p)) {
            int fd = real_openat(dirfd, path, flags, mode);
            if (fd < 0 && errno == ENOENT && isFakeDirectory(p))
                fd = real_openat(AT_FDCWD, emptyDirectory().c_str(), flags, mode);
            if (fd >= 0) {
                std::lock_guard lock(dirMutex());
                dirFds()[fd] = p;
            }
            return fd;
        }
    }
    return real_openat(dirfd, path, flags, mode);
}

int closeFd(int fd)
{
    STEREOD_REAL(close, CloseFn);
    if (isFakeFd(fd))
        return closeFile(fd) == 0 ? 0 : -1;
    if (anyLoaded()) {
        std::lock_guard lock(dirMutex());
        dirFds().erase(fd);
    }
    return real_close(fd);
}

int ioctlFd(int fd, unsigned long request, void* arg)
{
    const std::shared_ptr<OpenFile> file = findFile(fd);
    if (!file)
        return fail(EBADF);
    const int rc = file->device->ioctl(*file, request, arg);
    return rc < 0 ? fail(-rc) : rc;
}

void* mmapFd(void* addr, size_t length, int prot, int flags, int fd, off_t offset)
{
    const std::shared_ptr<OpenFile> file = findFile(fd);
    if (!file) {
        errno = EBADF;
        return MAP_FAILED;
    }
    int error = 0;
    void* mapped = file->device->mmap(*file, addr, length, prot, flags, offset, &error);
    if (mapped == nullptr) {
        errno = error;
        return MAP_FAILED;
    }
    noteMapped(mapped);
    return mapped;
}

void fillCharDevice(struct stat* st, const std::shared_ptr<Device>& device)
{
    std::memset(st, 0, sizeof *st);
    st->st_mode = S_IFCHR | 0660;
    st->st_nlink = 1;
    st->st_gid = 44; // the "video" group
    // Major 81 is V4L; minors far above any real node so no sysfs entry matches.
    st->st_rdev = makedev(81, 200 + (std::hash<std::string>{}(device->spec().path) % 50));
    st->st_blksize = 4096;
}

int statPath(const char* path, struct stat* st, bool follow)
{
    bool is_link = false;
    const std::shared_ptr<Device> device = findDeviceByPath(path);
    if (device) {
        lookupPath(path, &is_link);
        if (!device->stats().plugged)
            return fail(ENOENT);
        fillCharDevice(st, device);
        if (is_link && !follow) {
            st->st_mode = S_IFLNK | 0777;
            st->st_rdev = 0;
        }
        return 0;
    }
    return 1; // not fake
}

int pollFds(pollfd* fds, nfds_t count, int timeout_ms, const timespec* timeout,
            const sigset_t* mask)
{
    STEREOD_REAL(poll, PollFn);
    STEREOD_REAL(ppoll, PpollFn);
    bool any = false;
    for (nfds_t i = 0; i < count; ++i)
        any = any || isFakeFd(fds[i].fd);
    if (!any)
        return timeout_ms == INT_MIN ? real_ppoll(fds, count, timeout, mask)
                                     : real_poll(fds, count, timeout_ms);
    std::vector<short> asked(count);
    for (nfds_t i = 0; i < count; ++i) {
        asked[i] = fds[i].events;
        if (isFakeFd(fds[i].fd))
            fds[i].events = POLLIN; // the eventfd is readable whenever events are pending
    }
    const int rc = timeout_ms == INT_MIN ? real_ppoll(fds, count, timeout, mask)
                                         : real_poll(fds, count, timeout_ms);
    int ready = 0;
    for (nfds_t i = 0; i < count; ++i) {
        fds[i].events = asked[i];
        if (rc < 0)
            continue;
        if (isFakeFd(fds[i].fd))
            fds[i].revents =
                static_cast<short>(publishedEvents(fds[i].fd) & (asked[i] | POLLERR | POLLHUP));
        if (fds[i].revents != 0)
            ++ready;
    }
    return rc < 0 ? rc : ready;
}

} // namespace

// ---- the real functions, for the fake's own use ----------------------------------------

namespace real {
int open(const char* path, int flags, mode_t mode)
{
    STEREOD_REAL(openat, OpenatFn);
    return real_openat(AT_FDCWD, path, flags, mode);
}
int close(int fd)
{
    STEREOD_REAL(close, CloseFn);
    return real_close(fd);
}
ssize_t read(int fd, void* buf, size_t count)
{
    STEREOD_REAL(read, ReadFn);
    return real_read(fd, buf, count);
}
ssize_t write(int fd, const void* buf, size_t count)
{
    STEREOD_REAL(write, WriteFn);
    return real_write(fd, buf, count);
}
void* mmap(void* addr, size_t length, int prot, int flags, int fd, off_t offset)
{
    STEREOD_REAL(mmap, MmapFn);
    return real_mmap(addr, length, prot, flags, fd, offset);
}
int munmap(void* addr, size_t length)
{
    STEREOD_REAL(munmap, MunmapFn);
    return real_munmap(addr, length);
}
} // namespace real

} // namespace stereod::fake

using namespace stereod::fake;

#define STEREOD_EXPORT extern "C" __attribute__((visibility("default")))

namespace {
mode_t modeArg(int flags, va_list args)
{
    return (flags & (O_CREAT | O_TMPFILE)) != 0 ? static_cast<mode_t>(va_arg(args, int)) : 0;
}
} // namespace

STEREOD_EXPORT int open(const char* path, int flags, ...)
{
    va_list args;
    va_start(args, flags);
    const mode_t mode = modeArg(flags, args);
    va_end(args);
    return openPath(AT_FDCWD, path, flags, mode);
}

STEREOD_EXPORT int openat(int dirfd, const char* path, int flags, ...)
{
    va_list args;
    va_start(args, flags);
    const mode_t mode = modeArg(flags, args);
    va_end(args);
    return openPath(dirfd, path, flags, mode);
}

// On LP64, open64/openat64 are open/openat.
STEREOD_EXPORT int open64(const char* path, int flags, ...) __attribute__((alias("open")));
STEREOD_EXPORT int openat64(int dirfd, const char* path, int flags, ...)
    __attribute__((alias("openat")));

STEREOD_EXPORT int __open_2(const char* path, int flags)
{
    return openPath(AT_FDCWD, path, flags, 0);
}

STEREOD_EXPORT int __open64_2(const char* path, int flags)
{
    return openPath(AT_FDCWD, path, flags, 0);
}

STEREOD_EXPORT int __openat_2(int dirfd, const char* path, int flags)
{
    return openPath(dirfd, path, flags, 0);
}

STEREOD_EXPORT int __openat64_2(int dirfd, const char* path, int flags)
{
    return openPath(dirfd, path, flags, 0);
}

STEREOD_EXPORT int close(int fd)
{
    return closeFd(fd);
}

STEREOD_EXPORT int ioctl(int fd, unsigned long request, ...) noexcept
{
    va_list args;
    va_start(args, request);
    void* arg = va_arg(args, void*);
    va_end(args);
    if (isFakeFd(fd))
        return ioctlFd(fd, request, arg);
    STEREOD_REAL(ioctl, IoctlFn);
    return real_ioctl(fd, request, arg);
}

STEREOD_EXPORT void* mmap(void* addr, size_t length, int prot, int flags, int fd,
                          off_t offset) noexcept
{
    if (isFakeFd(fd))
        return mmapFd(addr, length, prot, flags, fd, offset);
    return real::mmap(addr, length, prot, flags, fd, offset);
}

STEREOD_EXPORT void* mmap64(void* addr, size_t length, int prot, int flags, int fd,
                            off64_t offset) noexcept
{
    return mmap(addr, length, prot, flags, fd, offset);
}

STEREOD_EXPORT int munmap(void* addr, size_t length) noexcept
{
    const int rc = real::munmap(addr, length);
    if (rc == 0)
        noteUnmap(addr);
    return rc;
}

STEREOD_EXPORT ssize_t read(int fd, void* buf, size_t count)
{
    if (isFakeFd(fd))
        return fail(EINVAL); // no V4L2_CAP_READWRITE
    return real::read(fd, buf, count);
}

STEREOD_EXPORT ssize_t write(int fd, const void* buf, size_t count)
{
    if (isFakeFd(fd))
        return fail(EINVAL);
    return real::write(fd, buf, count);
}

STEREOD_EXPORT int poll(pollfd* fds, nfds_t count, int timeout_ms)
{
    return pollFds(fds, count, timeout_ms < 0 ? -1 : timeout_ms, nullptr, nullptr);
}

STEREOD_EXPORT int ppoll(pollfd* fds, nfds_t count, const timespec* timeout, const sigset_t* mask)
{
    return pollFds(fds, count, INT_MIN, timeout, mask);
}

// libv4l2 and libv4lconvert reach the device only through syscall(2).
//
// The arguments are read as glibc's own syscall() reads them: all six, whatever the call
// passed, since a syscall passed on must get its sixth argument when it has one (futex
// with FUTEX_WAIT_BITSET does). The sixth comes from the caller's stack, past what a
// three-argument caller pushed: harmless there, but ASan flags the read, so this one
// function is not instrumented.
STEREOD_EXPORT __attribute__((no_sanitize("address"))) long syscall(long number, ...) noexcept
{
    va_list args;
    va_start(args, number);
    long a[6];
    for (long& v : a)
        v = va_arg(args, long);
    va_end(args);
    switch (number) {
    case SYS_openat:
        return openPath(static_cast<int>(a[0]), reinterpret_cast<const char*>(a[1]),
                        static_cast<int>(a[2]), static_cast<mode_t>(a[3]));
    case SYS_open:
        return openPath(AT_FDCWD, reinterpret_cast<const char*>(a[0]), static_cast<int>(a[1]),
                        static_cast<mode_t>(a[2]));
    case SYS_close:
        return closeFd(static_cast<int>(a[0]));
    case SYS_ioctl:
        if (isFakeFd(static_cast<int>(a[0])))
            return ioctlFd(static_cast<int>(a[0]), static_cast<unsigned long>(a[1]),
                           reinterpret_cast<void*>(a[2]));
        break;
    case SYS_read:
    case SYS_write:
        if (isFakeFd(static_cast<int>(a[0])))
            return fail(EINVAL);
        break;
    case SYS_mmap: {
        void* mapped =
            mmap(reinterpret_cast<void*>(a[0]), static_cast<size_t>(a[1]), static_cast<int>(a[2]),
                 static_cast<int>(a[3]), static_cast<int>(a[4]), static_cast<off_t>(a[5]));
        return reinterpret_cast<long>(mapped);
    }
    case SYS_munmap:
        return munmap(reinterpret_cast<void*>(a[0]), static_cast<size_t>(a[1]));
    default:
        break;
    }
    STEREOD_REAL(syscall, SyscallFn);
    return real_syscall(number, a[0], a[1], a[2], a[3], a[4], a[5]);
}

namespace {
// stat/lstat: a fake device (or its by-id link), a directory that only exists for fake
// entries (shown as the empty stand-in directory), or the real file.
int statAny(const char* path, struct stat* st, bool follow, StatFn real_fn)
{
    if (active()) {
        const int rc = statPath(path, st, follow);
        if (rc <= 0)
            return rc;
        if (isFakeDirectory(path)) {
            const int real_rc = real_fn(path, st);
            return real_rc == 0 ? 0 : real_fn(emptyDirectory().c_str(), st);
        }
    }
    return real_fn(path, st);
}
} // namespace

STEREOD_EXPORT int stat(const char* path, struct stat* st) noexcept
{
    STEREOD_REAL(stat, StatFn);
    return statAny(path, st, true, real_stat);
}

STEREOD_EXPORT int lstat(const char* path, struct stat* st) noexcept
{
    STEREOD_REAL(lstat, StatFn);
    return statAny(path, st, false, real_lstat);
}

STEREOD_EXPORT int stat64(const char* path, struct stat64* st) noexcept
{
    return stat(path, reinterpret_cast<struct stat*>(st));
}

STEREOD_EXPORT int lstat64(const char* path, struct stat64* st) noexcept
{
    return lstat(path, reinterpret_cast<struct stat*>(st));
}

STEREOD_EXPORT int fstat(int fd, struct stat* st) noexcept
{
    if (isFakeFd(fd)) {
        const std::shared_ptr<OpenFile> file = findFile(fd);
        if (file) {
            fillCharDevice(st, file->device);
            return 0;
        }
    }
    STEREOD_REAL(fstat, FstatFn);
    return real_fstat(fd, st);
}

STEREOD_EXPORT int fstat64(int fd, struct stat64* st) noexcept
{
    return fstat(fd, reinterpret_cast<struct stat*>(st));
}

STEREOD_EXPORT int fstatat(int dirfd, const char* path, struct stat* st, int flags) noexcept
{
    if (path[0] == '/' && active() && findDeviceByPath(path))
        return (flags & AT_SYMLINK_NOFOLLOW) != 0 ? lstat(path, st) : stat(path, st);
    STEREOD_REAL(fstatat, FstatatFn);
    return real_fstatat(dirfd, path, st, flags);
}

STEREOD_EXPORT int fstatat64(int dirfd, const char* path, struct stat64* st, int flags) noexcept
{
    return fstatat(dirfd, path, reinterpret_cast<struct stat*>(st), flags);
}

STEREOD_EXPORT int access(const char* path, int mode) noexcept
{
    if (active()) {
        if (const std::shared_ptr<Device> device = findDeviceByPath(path))
            return device->stats().plugged ? 0 : fail(ENOENT);
    }
    STEREOD_REAL(access, AccessFn);
    return real_access(path, mode);
}

STEREOD_EXPORT ssize_t readlink(const char* path, char* buf, size_t size) noexcept
{
    if (active()) {
        bool is_link = false;
        if (const std::shared_ptr<Device> device = lookupPath(path, &is_link)) {
            if (!device->stats().plugged)
                return fail(ENOENT);
            if (!is_link)
                return fail(EINVAL);
            const std::filesystem::path link(device->spec().by_id_path);
            const std::string target = std::filesystem::path(device->spec().path)
                                           .lexically_relative(link.parent_path())
                                           .string();
            const size_t n = std::min(size, target.size());
            std::memcpy(buf, target.data(), n);
            return static_cast<ssize_t>(n);
        }
    }
    STEREOD_REAL(readlink, ReadlinkFn);
    return real_readlink(path, buf, size);
}

STEREOD_EXPORT char* realpath(const char* path, char* resolved) noexcept
{
    if (path != nullptr && active()) {
        if (const std::shared_ptr<Device> device = findDeviceByPath(path)) {
            if (!device->stats().plugged) {
                errno = ENOENT;
                return nullptr;
            }
            const std::string& target = device->spec().path;
            char* out = resolved != nullptr ? resolved : static_cast<char*>(malloc(PATH_MAX));
            if (out == nullptr)
                return nullptr;
            std::strncpy(out, target.c_str(), PATH_MAX - 1);
            out[PATH_MAX - 1] = '\0';
            return out;
        }
    }
    STEREOD_REAL(realpath, RealpathFn);
    return real_realpath(path, resolved);
}

STEREOD_EXPORT DIR* opendir(const char* path)
{
    STEREOD_REAL(opendir, OpendirFn);
    if (active() && listsFakeEntries(path)) {
        DIR* dir = real_opendir(path);
        if (dir == nullptr && errno == ENOENT && isFakeDirectory(path))
            dir = real_opendir(emptyDirectory().c_str());
        trackDir(dir, path);
        return dir;
    }
    return real_opendir(path);
}

STEREOD_EXPORT DIR* fdopendir(int fd)
{
    STEREOD_REAL(fdopendir, FdopendirFn);
    DIR* dir = real_fdopendir(fd);
    if (dir != nullptr && anyLoaded()) {
        std::string path;
        {
            std::lock_guard lock(dirMutex());
            const auto it = dirFds().find(fd);
            if (it != dirFds().end()) {
                path = it->second;
                dirFds().erase(it);
            }
        }
        if (!path.empty())
            trackDir(dir, path);
    }
    return dir;
}

STEREOD_EXPORT dirent* readdir(DIR* dir)
{
    STEREOD_REAL(readdir, ReaddirFn);
    dirent* entry = real_readdir(dir);
    if (entry != nullptr || !anyLoaded())
        return entry;
    static_assert(sizeof(dirent) == sizeof(dirent64), "dirent and dirent64 share a layout on LP64");
    return reinterpret_cast<dirent*>(nextFakeEntry(dir));
}

STEREOD_EXPORT dirent64* readdir64(DIR* dir)
{
    STEREOD_REAL(readdir64, Readdir64Fn);
    dirent64* entry = real_readdir64(dir);
    if (entry != nullptr || !anyLoaded())
        return entry;
    return nextFakeEntry(dir);
}

STEREOD_EXPORT int closedir(DIR* dir)
{
    {
        std::lock_guard lock(dirMutex());
        dirs().erase(dir);
    }
    STEREOD_REAL(closedir, ClosedirFn);
    return real_closedir(dir);
}

namespace {
// Loads the description named by STEREOD_FAKE_V4L2 before main() when preloaded.
__attribute__((constructor)) void loadAtStart()
{
    ensureLoadedFromEnvironment();
}
} // namespace
