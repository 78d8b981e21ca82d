// All fake devices and open files of the process, the command interface (in-process
// functions and the control FIFO), and loading the description.

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <unordered_map>

#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/eventfd.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "tests/fake_v4l2/fake_internal.hpp"
#include "tests/fake_v4l2/fake_v4l2.hpp"

namespace stereod::fake {
namespace {

constexpr int kMaxFd = 1 << 16;

// Which fds are fake devices' files: read lock-free on every interposed call.
std::atomic<uint8_t> g_fake_fd[kMaxFd];
// poll events of each fake fd, published under the device lock whenever they change and
// read lock-free by poll(): sanitizer runtimes call poll's next definition (ours) in a
// state where our lock would be invisible to them.
std::atomic<short> g_fd_events[kMaxFd];
std::atomic<bool> g_loaded{false};
std::atomic<int> g_mappings{0};
// Addresses of live mappings of fake buffers (more than any test maps at once).
std::atomic<void*> g_mapped[1024];

__attribute__((tls_model("initial-exec"))) thread_local int t_passthrough = 0;
thread_local std::string t_last_error;

// Thread-safe: every member is guarded by `mutex`.
struct Registry {
    std::mutex mutex;
    std::vector<std::shared_ptr<Device>> devices;
    std::unordered_map<int, std::shared_ptr<OpenFile>> files;
    std::string control_fifo;
    std::thread fifo_thread;
    int fifo_stop_fd = -1;
    std::string empty_dir;
};

Registry& registry()
{
    // Never destroyed: interposed calls may come during and after static destruction.
    static Registry* r = new Registry;
    return *r;
}

int64_t monotonicNs()
{
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string normalize(const std::string& path)
{
    if (path.find("/.") == std::string::npos && path.find("//") == std::string::npos)
        return path;
    return std::filesystem::path(path).lexically_normal().string();
}

std::shared_ptr<Device> findDeviceLocked(Registry& r, const std::string& name)
{
    for (const auto& device : r.devices) {
        const DeviceSpec& spec = device->spec();
        if (spec.path == name || (!spec.by_id_path.empty() &&
                                  (spec.by_id_path == name ||
                                   std::filesystem::path(spec.by_id_path).filename() == name)))
            return device;
    }
    return nullptr;
}

std::shared_ptr<Device> findNamed(const char* name)
{
    if (name == nullptr)
        return nullptr;
    Registry& r = registry();
    std::lock_guard lock(r.mutex);
    return findDeviceLocked(r, normalize(name));
}

void stopFifoLocked(Registry& r, std::unique_lock<std::mutex>& lock)
{
    if (r.fifo_stop_fd >= 0) {
        const uint64_t one = 1;
        if (real::write(r.fifo_stop_fd, &one, sizeof one) < 0)
            std::perror("stereod fake V4L2: stop the control FIFO thread");
    }
    std::thread thread = std::move(r.fifo_thread);
    if (thread.joinable()) {
        lock.unlock();
        thread.join();
        lock.lock();
    }
    if (r.fifo_stop_fd >= 0)
        real::close(r.fifo_stop_fd);
    r.fifo_stop_fd = -1;
}

// Reads commands, one per line, from the FIFO until told to stop.
void fifoLoop(std::string path, int stop_fd)
{
    pthread_setname_np(pthread_self(), "fake-v4l2-ctl");
    Passthrough passthrough;
    const int fd = real::open(path.c_str(), O_RDWR | O_CLOEXEC | O_NONBLOCK, 0);
    if (fd < 0) {
        std::fprintf(stderr, "stereod fake V4L2: cannot open control FIFO %s: %s\n", path.c_str(),
                     std::strerror(errno));
        return;
    }
    std::string pending;
    char chunk[512];
    for (;;) {
        pollfd fds[2] = {{fd, POLLIN, 0}, {stop_fd, POLLIN, 0}};
        if (::poll(fds, 2, -1) < 0 && errno != EINTR)
            break;
        if (fds[1].revents != 0)
            break;
        const ssize_t n = real::read(fd, chunk, sizeof chunk);
        if (n <= 0)
            continue;
        pending.append(chunk, static_cast<size_t>(n));
        size_t newline = 0;
        while ((newline = pending.find('\n')) != std::string::npos) {
            const std::string line = pending.substr(0, newline);
            pending.erase(0, newline + 1);
            if (!line.empty() && stereod_fake_v4l2_command(line.c_str()) != 0)
                std::fprintf(stderr, "stereod fake V4L2: command '%s': %s\n", line.c_str(),
                             stereod_fake_v4l2_last_error());
        }
    }
    real::close(fd);
}

int setError(int rc, const std::string& message)
{
    t_last_error = message;
    return rc;
}

} // namespace

Passthrough::Passthrough() noexcept
{
    ++t_passthrough;
}

Passthrough::~Passthrough()
{
    --t_passthrough;
}

bool Passthrough::active() noexcept
{
    return t_passthrough > 0;
}

bool isFakeFd(int fd) noexcept
{
    return fd >= 0 && fd < kMaxFd && g_fake_fd[fd].load(std::memory_order_relaxed) != 0;
}

void publishEvents(int fd, short events) noexcept
{
    if (fd >= 0 && fd < kMaxFd)
        g_fd_events[fd].store(events, std::memory_order_release);
}

short publishedEvents(int fd) noexcept
{
    return fd >= 0 && fd < kMaxFd ? g_fd_events[fd].load(std::memory_order_acquire) : POLLNVAL;
}

bool anyLoaded() noexcept
{
    return g_loaded.load(std::memory_order_acquire);
}

void ensureLoadedFromEnvironment() noexcept
{
    static std::atomic<bool> checked{false};
    if (checked.load(std::memory_order_acquire) || checked.exchange(true))
        return;
    const char* path = std::getenv("STEREOD_FAKE_V4L2");
    if (path == nullptr || *path == '\0')
        return;
    if (stereod_fake_v4l2_load(path) != 0)
        std::fprintf(stderr, "stereod fake V4L2: %s\n", stereod_fake_v4l2_last_error());
}

std::shared_ptr<Device> lookupPath(const std::string& raw, bool* is_link)
{
    const std::string path = normalize(raw);
    Registry& r = registry();
    std::lock_guard lock(r.mutex);
    for (const auto& device : r.devices) {
        if (device->spec().path == path) {
            *is_link = false;
            return device;
        }
        if (!device->spec().by_id_path.empty() && device->spec().by_id_path == path) {
            *is_link = true;
            return device;
        }
    }
    return nullptr;
}

std::shared_ptr<Device> findDeviceByPath(const char* path)
{
    bool is_link = false;
    return lookupPath(path, &is_link);
}

std::shared_ptr<OpenFile> findFile(int fd)
{
    Registry& r = registry();
    std::lock_guard lock(r.mutex);
    const auto it = r.files.find(fd);
    return it == r.files.end() ? nullptr : it->second;
}

int openDevice(const std::shared_ptr<Device>& device, int flags)
{
    int efd_flags = 0;
    if (flags & O_NONBLOCK)
        efd_flags |= EFD_NONBLOCK;
    if (flags & O_CLOEXEC)
        efd_flags |= EFD_CLOEXEC;
    const int fd = eventfd(0, efd_flags);
    if (fd < 0)
        return -errno;
    if (fd >= kMaxFd) {
        real::close(fd);
        return -EMFILE;
    }
    auto file = std::make_shared<OpenFile>();
    file->fd = fd;
    file->device = device;
    const int rc = device->attach(file);
    if (rc != 0) {
        real::close(fd);
        return rc;
    }
    Registry& r = registry();
    {
        std::lock_guard lock(r.mutex);
        r.files[fd] = file;
    }
    g_fake_fd[fd].store(1, std::memory_order_relaxed);
    return fd;
}

int closeFile(int fd)
{
    std::shared_ptr<OpenFile> file;
    Registry& r = registry();
    {
        std::lock_guard lock(r.mutex);
        const auto it = r.files.find(fd);
        if (it != r.files.end()) {
            file = it->second;
            r.files.erase(it);
        }
    }
    if (file)
        file->device->detach(file.get());
    g_fake_fd[fd].store(0, std::memory_order_relaxed);
    return real::close(fd);
}

void noteUnmap(void* addr)
{
    // Lock-free unless `addr` is a fake buffer: munmap also runs inside sanitizer
    // runtimes (e.g. while a report is printed) where taking our locks could deadlock.
    if (g_mappings.load(std::memory_order_relaxed) == 0)
        return;
    bool ours = false;
    for (std::atomic<void*>& slot : g_mapped) {
        void* expected = addr;
        if (slot.load(std::memory_order_relaxed) == addr &&
            slot.compare_exchange_strong(expected, nullptr)) {
            ours = true;
            g_mappings.fetch_sub(1, std::memory_order_relaxed);
            break;
        }
    }
    if (!ours)
        return;
    std::vector<std::shared_ptr<Device>> devices;
    {
        Registry& r = registry();
        std::lock_guard lock(r.mutex);
        devices = r.devices;
    }
    for (const auto& device : devices)
        if (device->unmapped(addr))
            return;
}

void noteMapped(void* addr)
{
    for (std::atomic<void*>& slot : g_mapped) {
        void* expected = nullptr;
        if (slot.load(std::memory_order_relaxed) == nullptr &&
            slot.compare_exchange_strong(expected, addr)) {
            g_mappings.fetch_add(1, std::memory_order_relaxed);
            return;
        }
    }
}

std::vector<DirEntry> fakeEntriesOf(const std::string& raw)
{
    std::string directory = normalize(raw);
    while (directory.size() > 1 && directory.back() == '/')
        directory.pop_back();
    std::vector<DirEntry> entries;
    Registry& r = registry();
    std::lock_guard lock(r.mutex);
    for (const auto& device : r.devices) {
        if (!device->stats().plugged)
            continue;
        const std::filesystem::path path(device->spec().path);
        if (path.parent_path() == directory)
            entries.push_back({path.filename().string(), false});
        if (!device->spec().by_id_path.empty()) {
            const std::filesystem::path link(device->spec().by_id_path);
            if (link.parent_path() == directory)
                entries.push_back({link.filename().string(), true});
        }
    }
    return entries;
}

bool isFakeDirectory(const std::string& raw)
{
    std::string directory = normalize(raw);
    while (directory.size() > 1 && directory.back() == '/')
        directory.pop_back();
    Registry& r = registry();
    std::lock_guard lock(r.mutex);
    for (const auto& device : r.devices)
        if (!device->spec().by_id_path.empty()) {
            // Every ancestor of a by-id link (e.g. /dev/v4l and /dev/v4l/by-id).
            for (std::filesystem::path p =
                     std::filesystem::path(device->spec().by_id_path).parent_path();
                 p.has_relative_path(); p = p.parent_path())
                if (p == directory)
                    return true;
        }
    return false;
}

std::string emptyDirectory()
{
    Registry& r = registry();
    std::lock_guard lock(r.mutex);
    return r.empty_dir;
}

} // namespace stereod::fake

using namespace stereod::fake;

extern "C" {

__attribute__((visibility("default"))) int stereod_fake_v4l2_load(const char* description_path)
{
    Passthrough passthrough;
    stereod_fake_v4l2_unload();
    Description description;
    try {
        description = loadDescription(description_path != nullptr ? description_path : "");
    } catch (const std::exception& e) {
        return setError(-EINVAL, e.what());
    }
    Registry& r = registry();
    std::unique_lock lock(r.mutex);
    const int64_t epoch = monotonicNs();
    for (size_t i = 0; i < description.devices.size(); ++i)
        r.devices.push_back(std::make_shared<Device>(
            description.devices[i], description.seed + static_cast<uint32_t>(i), epoch));
    if (r.empty_dir.empty()) {
        char dir[] = "/tmp/stereod-fake-v4l2-XXXXXX";
        if (mkdtemp(dir) != nullptr)
            r.empty_dir = dir;
    }
    if (!description.control_fifo.empty()) {
        const std::string& fifo = description.control_fifo;
        struct stat st {};
        if (::stat(fifo.c_str(), &st) != 0 && mkfifo(fifo.c_str(), 0600) != 0) {
            const std::string why = std::strerror(errno);
            lock.unlock();
            stereod_fake_v4l2_unload();
            return setError(-EIO, fifo + ": cannot create the control FIFO: " + why);
        }
        r.control_fifo = fifo;
        r.fifo_stop_fd = eventfd(0, EFD_CLOEXEC);
        // The library may be loaded before the program blocks the signals it waits for
        // (stereod takes SIGTERM on a thread of its own, with sigtimedwait): a thread started now
        // must not be the one the kernel picks to deliver them, or the default action kills the
        // process.
        sigset_t all;
        sigset_t previous;
        sigfillset(&all);
        pthread_sigmask(SIG_SETMASK, &all, &previous);
        r.fifo_thread = std::thread(fifoLoop, fifo, r.fifo_stop_fd);
        pthread_sigmask(SIG_SETMASK, &previous, nullptr);
    }
    g_loaded.store(true, std::memory_order_release);
    return 0;
}

__attribute__((visibility("default"))) void stereod_fake_v4l2_unload(void)
{
    Passthrough passthrough;
    Registry& r = registry();
    std::unique_lock lock(r.mutex);
    stopFifoLocked(r, lock);
    std::vector<std::shared_ptr<Device>> devices = std::move(r.devices);
    r.devices.clear();
    g_loaded.store(false, std::memory_order_release);
    lock.unlock();
    for (const auto& device : devices)
        device->shutdown();
}

__attribute__((visibility("default"))) int stereod_fake_v4l2_command(const char* line)
{
    std::istringstream in(line != nullptr ? line : "");
    std::string verb;
    std::string name;
    in >> verb >> name;
    const std::shared_ptr<Device> device = findNamed(name.c_str());
    if (verb.empty() || name.empty())
        return setError(-EINVAL, "a command is 'VERB DEVICE [ARGS]'");
    if (!device)
        return setError(-ENOENT, "no fake device '" + name + "'");
    if (verb == "unplug") {
        device->unplug();
    } else if (verb == "replug") {
        device->replug();
    } else if (verb == "stall" || verb == "drop") {
        int64_t value = -1;
        if (!(in >> value) || value < 0)
            return setError(-EINVAL, verb + " needs a count >= 0");
        if (verb == "stall")
            device->stall(value);
        else
            device->drop(static_cast<uint32_t>(value));
    } else if (verb == "corrupt") {
        int64_t frames = -1;
        std::string kind;
        if (!(in >> frames >> kind) || frames < 0)
            return setError(-EINVAL, "corrupt needs N and truncated|bytesused|error");
        if (kind == "truncated")
            device->corrupt(static_cast<uint32_t>(frames), CorruptKind::Truncated);
        else if (kind == "bytesused")
            device->corrupt(static_cast<uint32_t>(frames), CorruptKind::BytesUsed);
        else if (kind == "error")
            device->corrupt(static_cast<uint32_t>(frames), CorruptKind::Error);
        else
            return setError(-EINVAL,
                            "corrupt kind '" + kind + "' is not truncated, bytesused or error");
    } else {
        return setError(-EINVAL, "unknown command '" + verb + "'");
    }
    return 0;
}

__attribute__((visibility("default"))) int stereod_fake_v4l2_unplug(const char* device)
{
    return stereod_fake_v4l2_command((std::string("unplug ") + (device ? device : "")).c_str());
}

__attribute__((visibility("default"))) int stereod_fake_v4l2_replug(const char* device)
{
    return stereod_fake_v4l2_command((std::string("replug ") + (device ? device : "")).c_str());
}

__attribute__((visibility("default"))) int stereod_fake_v4l2_stall(const char* device,
                                                                   int32_t milliseconds)
{
    return stereod_fake_v4l2_command(
        (std::string("stall ") + (device ? device : "") + " " + std::to_string(milliseconds))
            .c_str());
}

__attribute__((visibility("default"))) int stereod_fake_v4l2_drop(const char* device,
                                                                  int32_t frames)
{
    return stereod_fake_v4l2_command(
        (std::string("drop ") + (device ? device : "") + " " + std::to_string(frames)).c_str());
}

__attribute__((visibility("default"))) int
stereod_fake_v4l2_corrupt(const char* device, int32_t frames, const char* kind)
{
    return stereod_fake_v4l2_command((std::string("corrupt ") + (device ? device : "") + " " +
                                      std::to_string(frames) + " " + (kind ? kind : ""))
                                         .c_str());
}

__attribute__((visibility("default"))) int stereod_fake_v4l2_stats(const char* name,
                                                                   struct StereodFakeV4l2Stats* out)
{
    const std::shared_ptr<Device> device = findNamed(name);
    if (!device || out == nullptr)
        return setError(-ENOENT, std::string("no fake device '") + (name ? name : "") + "'");
    *out = device->stats();
    return 0;
}

__attribute__((visibility("default"))) const char* stereod_fake_v4l2_last_error(void)
{
    return t_last_error.c_str();
}

} // extern "C"
