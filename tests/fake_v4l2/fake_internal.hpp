#pragma once
// Internals of the fake V4L2 device (see fake_v4l2.hpp for what it promises).

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <linux/videodev2.h>
#include <opencv2/core/mat.hpp>
#include <sys/types.h>

#include "tests/fake_v4l2/fake_v4l2.hpp"

namespace stereod::fake {

// ---- description ------------------------------------------------------------------

struct SizeSpec {
    uint32_t width = 0;
    uint32_t height = 0;
    std::vector<double> fps; // offered rates, first is the default
};

struct FormatSpec {
    uint32_t fourcc = 0; // V4L2_PIX_FMT_GREY / YUYV / MJPEG / RGB24 / BGR24
    std::vector<SizeSpec> sizes;
};

enum class ControlType { Integer, Boolean, Menu };

struct ControlSpec {
    uint32_t id = 0;
    std::string name;
    ControlType type = ControlType::Integer;
    int32_t minimum = 0;
    int32_t maximum = 0;
    int32_t step = 1;
    int32_t default_value = 0;
    std::vector<std::string> menu; // menu item names, index = value
};

struct DeviceSpec {
    std::string path;       // absolute device path
    std::string by_id_path; // /dev/v4l/by-id/NAME or empty
    std::string driver = "uvcvideo";
    std::string card;
    std::string bus_info;
    std::string images_glob;
    std::vector<std::string> image_files;
    int jpeg_quality = 90;
    std::vector<FormatSpec> formats;
    double jitter_ms = 0.0;
    double phase_ms = 0.0;
    double clock_offset_ms = 0.0;
    double clock_skew_ppm = 0.0;
    uint32_t drop_every = 0;
    bool monotonic_stamps = true;
    std::vector<ControlSpec> controls; // sorted by id
};

struct Description {
    std::string source_path; // the YAML file
    std::string control_fifo;
    uint32_t seed = 1;
    std::vector<DeviceSpec> devices;
};

// Parses and checks a description; throws std::runtime_error naming the file, the line
// and the key at fault.
Description loadDescription(const std::string& path);

// ---- frames -----------------------------------------------------------------------

// Bytes of one frame in `fourcc` at the size: GREY w*h, YUYV 2*w*h, RGB3/BGR3 3*w*h, MJPG
// the buffer size a driver would allocate (2*w*h).
uint32_t imageBufferSize(uint32_t fourcc, uint32_t width, uint32_t height);
uint32_t bytesPerLine(uint32_t fourcc, uint32_t width);

// The device's images converted to the format and size: one byte string per image
// (MJPG: a JPEG of quality `jpeg_quality`). Throws std::runtime_error if an image does
// not load.
std::vector<std::vector<uint8_t>> renderFrames(const std::vector<std::string>& image_files,
                                               uint32_t fourcc, uint32_t width, uint32_t height,
                                               int jpeg_quality);

// ---- the real libc functions (next definition after ours) ---------------------------

namespace real {
int open(const char* path, int flags, mode_t mode);
int close(int fd);
ssize_t read(int fd, void* buf, size_t count);
ssize_t write(int fd, const void* buf, size_t count);
void* mmap(void* addr, size_t length, int prot, int flags, int fd, off_t offset);
int munmap(void* addr, size_t length);
} // namespace real

// ---- device -----------------------------------------------------------------------

class Device;

// One open() of a fake device. The fd is a real eventfd that carries poll readiness.
struct OpenFile {
    int fd = -1;
    std::shared_ptr<Device> device;
    uint64_t generation = 0; // device generation at open; differs after unplug
    bool signalled = false;  // eventfd counter > 0 (guarded by device mutex)
};

enum class CorruptKind { Truncated, BytesUsed, Error };

// Thread-safe: every member function locks the device mutex; one producer thread per
// streaming device.
class Device {
  public:
    Device(DeviceSpec spec, uint32_t seed, int64_t epoch_ns);
    ~Device();

    const DeviceSpec& spec() const { return spec_; }

    // 0 or -errno (ENOENT when unplugged).
    int attach(const std::shared_ptr<OpenFile>& file);
    void detach(OpenFile* file);

    // The ioctl, with errno semantics: returns 0 or -errno.
    int ioctl(OpenFile& file, unsigned long request, void* arg);
    // mmap of a buffer: the address, or nullptr with *error = errno.
    void* mmap(OpenFile& file, void* addr, size_t length, int prot, int flags, off_t offset,
               int* error);
    // A munmap of an address this device handed out (true if it was one).
    bool unmapped(void* addr);

    void unplug();
    void replug();
    void stall(int64_t ms);
    void drop(uint32_t frames);
    void corrupt(uint32_t frames, CorruptKind kind);
    void shutdown(); // stop streaming for good (unload)

    StereodFakeV4l2Stats stats();

  private:
    enum class BufferState { Dequeued, Queued, Active, Done };
    struct Buffer {
        BufferState state = BufferState::Dequeued;
        uint32_t bytesused = 0;
        uint32_t flags = 0;
        timeval timestamp{};
        uint32_t sequence = 0;
        int mapped = 0;
    };
    struct Mapping {
        void* addr;
        int buffer;
    };

    bool alive(const OpenFile& file) const;
    bool ownsQueue(const OpenFile& file) const;
    short pollEventsLocked(const OpenFile& file) const;
    void updateReadinessLocked();
    const FormatSpec* findFormat(uint32_t fourcc) const;
    void adjustFormat(v4l2_pix_format& pix) const;
    const SizeSpec* currentSize() const;
    const ControlSpec* findControl(uint32_t id) const;
    int32_t& controlValue(uint32_t id);
    int setControlLocked(uint32_t id, int32_t value, bool apply);
    uint32_t controlFlags(const ControlSpec& control) const;
    int queryCtrl(v4l2_queryctrl& q) const;
    int queryExtCtrl(v4l2_query_ext_ctrl& q) const;
    int extCtrls(unsigned long request, v4l2_ext_controls& ctrls);
    int reqbufs(OpenFile& file, v4l2_requestbuffers& req);
    void fillBuffer(uint32_t index, v4l2_buffer& buf) const;
    int qbuf(OpenFile& file, v4l2_buffer& buf);
    int dqbuf(OpenFile& file, std::unique_lock<std::mutex>& lock, v4l2_buffer& buf);
    int streamon(OpenFile& file);
    void streamoffLocked(std::unique_lock<std::mutex>& lock);
    void freeBuffersLocked();
    void produce();
    int64_t reportedStampNs(int64_t monotonic_ns) const;

    const DeviceSpec spec_;
    const int64_t epoch_ns_; // CLOCK_MONOTONIC at load: the skew's origin

    mutable std::mutex mutex_;
    std::condition_variable cv_; // frame done, stream stopped, unplug, stop request
    std::vector<OpenFile*> files_;
    uint64_t generation_ = 1; // bumped at unplug: older OpenFiles are dead
    bool plugged_ = true;

    uint32_t pixelformat_ = 0;
    uint32_t width_ = 0;
    uint32_t height_ = 0;
    double fps_ = 0.0;
    std::map<uint32_t, int32_t> control_values_;

    const OpenFile* owner_ = nullptr; // the open file that owns the buffer queue
    std::vector<Buffer> buffers_;
    uint32_t buffer_stride_ = 0; // bytes between buffer offsets (page multiple)
    uint32_t size_image_ = 0;
    int memfd_ = -1;
    uint8_t* memory_ = nullptr; // the producer's mapping of all buffers
    size_t memory_bytes_ = 0;
    std::vector<Mapping> mappings_;
    std::deque<uint32_t> queued_;
    std::deque<uint32_t> done_;
    bool streaming_ = false;
    bool stop_producer_ = false;
    std::thread producer_;

    std::map<uint64_t, std::vector<std::vector<uint8_t>>> frame_cache_;
    const std::vector<std::vector<uint8_t>>* frames_ = nullptr;

    uint64_t sequence_ = 0;
    int64_t stall_until_ns_ = 0;
    uint32_t drop_pending_ = 0;
    uint32_t corrupt_pending_ = 0;
    CorruptKind corrupt_kind_ = CorruptKind::Truncated;
    std::mt19937_64 rng_;
    uint64_t frames_done_ = 0;
    uint64_t frames_lost_ = 0;
};

// ---- registry (all devices and open files of the process) ---------------------------

// Is `fd` a fake device's file? Lock-free; false when nothing is loaded.
bool isFakeFd(int fd) noexcept;
// The poll events of a fake fd as last published by its device (lock-free).
void publishEvents(int fd, short events) noexcept;
short publishedEvents(int fd) noexcept;
// True when any description is loaded (lock-free).
bool anyLoaded() noexcept;
// Loads STEREOD_FAKE_V4L2 once, on the first call that names a path.
void ensureLoadedFromEnvironment() noexcept;

std::shared_ptr<Device> findDeviceByPath(const char* path);
std::shared_ptr<OpenFile> findFile(int fd);
// Opens a fake device: the new fd, or -errno.
int openDevice(const std::shared_ptr<Device>& device, int flags);
// Closes a fake fd (the eventfd too). Returns 0.
int closeFile(int fd);
// munmap bookkeeping for addresses handed out by fake devices.
void noteMapped(void* addr);
void noteUnmap(void* addr);
// Entries a directory listing adds: name and whether it is a symlink.
struct DirEntry {
    std::string name;
    bool symlink;
};
std::vector<DirEntry> fakeEntriesOf(const std::string& directory);
// For a fake path (device or by-id link): the device, and whether the path is the link.
std::shared_ptr<Device> lookupPath(const std::string& path, bool* is_link);
// A directory that holds fake entries (e.g. /dev/v4l/by-id) even if it does not exist.
bool isFakeDirectory(const std::string& path);
// An empty real directory used to stand in for a fake directory.
std::string emptyDirectory();

// RAII guard: while alive on a thread, the interposed functions forward everything (so
// the fake's own use of libc, e.g. loading images, never re-enters it).
class Passthrough {
  public:
    Passthrough() noexcept;
    ~Passthrough();
    Passthrough(const Passthrough&) = delete;
    Passthrough& operator=(const Passthrough&) = delete;
    static bool active() noexcept;
};

} // namespace stereod::fake
