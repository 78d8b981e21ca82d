#pragma once
// The replay of a recording (replay/recording.hpp) or of a ROS 2 bag in MCAP
// (replay/mcap_recording.hpp: any bag with two sensor_msgs/msg/Image topics) behind the
// same FrameSource interface as the cameras.
//
// Two pacings:
//  - paced: pairs are delivered at their recorded time spacing, like live cameras
//    (drop-oldest push into the ring; a slow worker loses pairs, as it would live). A
//    stamp that steps back (a recording spliced from two runs) is warned about once, at
//    the open; that pair comes one frame period after the one before, and the pace goes
//    on from the new stamps;
//  - lockstep: as fast as the worker takes them, waiting for room in the ring and for
//    free buffers; nothing is dropped, so a run is repeatable (tests, offline runs).
//
// Every delivered frame is stamped on CLOCK_MONOTONIC at delivery (Frame::stamp_ns); the
// recorded stamp is kept in Frame::source_stamp_ns, and the right frame's stamp keeps the
// recorded right-minus-left skew. Pair index and frame sequence numbers are
// `pass * pairCount() + position in the recording`: they increase across loops, and a
// skipped pair leaves a gap, as a dropped camera frame would.
//
// Bad input is never fatal: a missing, corrupt or truncated image, a file that is not a
// regular one (a row pointing at /dev/zero), or an image whose size differs from the first
// readable pair's makes the pair skipped, counted (bad_frames of its side) and logged once
// per file. Sizes are read from the PNG or JPEG header, or the bag's Image message, before
// decoding (replay/image_file.hpp, replay/image_message.hpp): an image of another size,
// or, in the first pair, one larger than 8192x8192, is never decoded. Only a recording
// with no readable pair at all fails start(). A pass that later finds no readable pair
// (files removed, the process out of descriptors) puts the source in state Failed and
// is tried again, backing off from kRetryMinNs to kRetryMaxNs, until pairs are readable
// again: the replay recovers, as a camera that comes back does.
//
// Frames come from a FramePool sized from the first readable pair and allocated in the
// constructor (a side whose first pair has colour, with a colour plane, filled with the
// grey of a later grey image); PNG and JPEG decode into images kept from frame to frame
// (libpng's row list is its one allocation per PNG; other formats go through
// cv::imdecode, which allocates); nothing else is allocated per frame.
//
// Thread-safety: as FrameSource: start()/stop() from one controlling thread, status()
// and the const getters from any thread. One replay thread delivers the pairs; on its
// path into the ring it takes no lock.
//
// Lifetime: the frames live in this source's pool, so every pair it delivered must be
// gone (popped and released, or the ring destroyed) before the source is destroyed. The
// safe order: stop(), drain or destroy the ring, destroy the source. (A source destroyed
// with frames still out leaks its pool, with an error in the log, rather than free it
// under them.)

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "base/rate_estimate.hpp"
#include "base/rolling_window.hpp"
#include "capture/frame_pool.hpp"
#include "capture/frame_source.hpp"
#include "replay/mcap_recording.hpp"
#include "replay/recording.hpp"
#include "replay/replay_pacing.hpp"

namespace stereod {

struct ReplayOptions {
    std::string path; // a recording directory, a folder of left*/right*, or an
                      // MCAP file (recognised by its magic bytes)
    // The image topics of an MCAP bag; empty: /stereo/{left,right}/image_raw, or the one
    // pair of image topics whose names say left and right (indexMcapStereo()).
    std::string left_topic;
    std::string right_topic;
    ReplayPacing pacing = ReplayPacing::Paced;
    bool loop = true;  // start over at the end instead of finishing
    double fps = 10.0; // nominal rate of a plain folder (no frames.csv)
    // Pairs that can be in flight at once (filled by the source, queued in the ring,
    // held by the worker). At least ring capacity + 2, or paced replay drops pairs for
    // want of buffers (lockstep waits for them instead).
    std::size_t pool_pairs = 8;
    // Keep the left camera's colour where the recording has it (colour PNG/JPEG files,
    // rgb8/bgr8/yuv422 bag images): Frame::colour. A colour PNG as `stereoctl record`
    // writes it is then decoded once, in colour, its grey made from that; a colour JPEG
    // is decoded a second time (replay/image_decode.hpp). Grey recordings are unaffected
    // either way. Off: no colour is decoded at all (source.replay.colour none).
    bool keep_colour = true;
    // The same for the right camera's images (source.replay.colour both).
    bool keep_right_colour = false;
};

class ReplaySource final : public FrameSource {
  public:
    // Reads the recording's index and decodes pairs up to the first readable one to learn
    // the frame size; allocates the pool. Never throws for a bad recording: the source is
    // then in state Failed, status().last_error says why and start() returns the error.
    explicit ReplaySource(ReplayOptions options);
    ~ReplaySource() override;

    ReplaySource(const ReplaySource&) = delete;
    ReplaySource& operator=(const ReplaySource&) = delete;

    // Starts the replay thread at the first pair. Returns 0; -ENOENT / -EINVAL (and the
    // reason in status().last_error, naming the path) when nothing is readable; -EBUSY
    // when already running (or trying again after a pass with nothing readable).
    int start(PairRing& ring) override;

    // Stops and joins the replay thread, promptly even in the middle of a long paced
    // gap. In lockstep mode it also stops `ring` (a producer blocked in pushWait() only
    // wakes that way): the owner calls ring.restart() before using the ring again.
    void stop() noexcept override;

    SourceStatus status() const override;

    // Size of the first readable pair; empty when nothing is readable.
    cv::Size frameSize() const override { return frame_size_; }
    bool keepsEveryPair() const noexcept override;

    // The recording's calibration.yaml, or empty when it has none (the service uses it
    // when no calibration is given).
    const std::string& calibrationPath() const noexcept { return recording_.calibration_path; }
    // A bag's camera_info pair (the first message of each side), when it has one.
    const std::optional<std::pair<ros2::CameraInfo, ros2::CameraInfo>>&
    bagCameraInfo() const noexcept
    {
        return bag_camera_info_;
    }
    // Pairs listed in the recording (readable or not).
    std::size_t pairCount() const noexcept { return recording_.entries.size(); }
    const ReplayOptions& options() const noexcept { return options_; }

  private:
    // Why a pair was skipped, for the count and the once-per-file warning.
    struct BadPair {
        int side = 0;     // 0 left, 1 right
        std::string path; // the file at fault
        std::string reason;
        int code = 0; // errno: ENOENT missing, EINVAL undecodable or wrong size
    };

    void run() noexcept;
    // Indexes an MCAP bag into recording_ (entries without paths) and bag_pairs_. Throws
    // mcap::McapError.
    void openBag();
    // Decodes entry `i` into left_image_/right_image_. False (and `bad` filled) when the
    // pair cannot be used.
    bool decodePair(std::size_t i, BadPair& bad);
    // Works out when each pair is due in a pass (schedule_ns_) and the frame period;
    // warns once when the stamps step back.
    void planSchedule();
    void reportBadPair(std::size_t i, const BadPair& bad);
    // Takes a free frame of `pool`; with `wait` (lockstep) waits for one, and gives an empty
    // handle only when stopping.
    FrameHandle acquireFrame(FramePool& pool, bool wait);
    // Sleeps until CLOCK_MONOTONIC reaches `deadline_ns` or stop() is called; false when
    // stopping.
    bool sleepUntil(int64_t deadline_ns);
    void recordDelivery(int64_t stamp_ns, int64_t skew_ns) noexcept;
    // Records a problem for status() and enters state Failed.
    void fail(const std::string& message);
    // The last bad pair reported (its file and reason), for the log.
    std::string lastBadPair() const;

    // A pass with no readable pair is tried again after this, doubling up to the maximum.
    static constexpr int64_t kRetryMinNs = 100'000'000;
    static constexpr int64_t kRetryMaxNs = 5'000'000'000;

    const ReplayOptions options_;
    Recording recording_;
    // An MCAP bag: the reader (used by the constructor, then by the replay thread only),
    // where each pair's messages are, and its camera_info.
    std::unique_ptr<mcap::Reader> bag_;
    std::vector<McapPair> bag_pairs_;
    std::optional<std::pair<ros2::CameraInfo, ros2::CameraInfo>> bag_camera_info_;
    cv::Size frame_size_;
    // When each pair is due, in ns after the pass's first pair: the recorded spacing,
    // except that a stamp stepping back counts as one period (planSchedule()).
    std::vector<int64_t> schedule_ns_;
    int64_t period_ns_ = 0;           // the mean recorded step forward (or the nominal rate's)
    int open_error_ = 0;              // negative errno when nothing is readable
    std::unique_ptr<FramePool> pool_; // grey frames, for the sides kept grey, or none
    std::unique_ptr<FramePool> colour_pool_; // frames with a colour plane, or none
    FramePool* left_pool_ = nullptr;         // one of the two (borrowed)
    FramePool* right_pool_ = nullptr;

    // Replay thread only (the controlling thread touches them only while it is not running).
    std::vector<uint8_t> warned_; // per entry and side: already logged
    cv::Mat left_image_;          // last decoded images (imdecode's buffers)
    cv::Mat right_image_;
    cv::Mat left_colour_;             // the left image's colour (BGR); empty when it has none
    cv::Mat right_colour_;            // the same for the right image (keep_right_colour)
    std::vector<uint8_t> file_bytes_; // the image file being decoded, capacity kept
    uint64_t next_pass_ = 0;          // loops continue the numbering after a restart

    PairRing* ring_ = nullptr; // borrowed between start() and stop()
    std::thread thread_;

    // stop() sets stop_requested_ under wake_mutex_ and notifies wake_cv_, so the replay
    // thread's timed waits end at once. Only those waits (the pacing between pairs, the
    // lockstep wait for a free buffer) take this mutex; the ring path (acquire, copy,
    // stamp, push) takes none.
    std::mutex wake_mutex_;
    std::condition_variable wake_cv_;
    std::atomic<bool> stop_requested_{false};
    std::atomic<bool> thread_done_{true}; // run() has returned (the thread may be joined)

    // Status: counters are atomics written by the replay thread; strings are guarded by
    // status_mutex_ and written only on the (rare) error paths.
    std::atomic<SourceState> state_{SourceState::Stopped};
    std::atomic<uint64_t> pairs_{0};
    std::atomic<uint64_t> frames_[2]{};
    std::atomic<uint64_t> bad_frames_[2]{};
    std::atomic<uint64_t> dropped_{0}; // pairs skipped for want of pool buffers
    RateEstimate<32> fps_; // delivered pairs (restarted by start() before the thread runs)
    RollingWindow<kSkewWindowPairs> skew_; // recorded right - left of recent pairs
    mutable std::mutex status_mutex_;
    std::string last_error_;      // guarded by status_mutex_
    std::string camera_error_[2]; // guarded by status_mutex_
};

} // namespace stereod
