#pragma once
// Recordings on disk: the format the recorder writes and the replay source reads.
//
//   DIR/frames.csv         header `index,left_stamp_ns,right_stamp_ns,left,right`, then one
//                          row per pair; file names relative to DIR (no commas, no
//                          newlines in them); stamps in ns on the recording's clock
//                          (CLOCK_MONOTONIC for live recordings)
//   DIR/left/NNNNNN.png    8-bit grayscale, lossless
//   DIR/right/NNNNNN.png
//   DIR/calibration.yaml   optional: the calibration the pairs were taken with
//
// A plain folder of `left*` / `right*` images is read as a recording too: the images are
// sorted by name and paired by order, stamps follow from a nominal frame rate.

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "base/unique_fd.hpp"

namespace stereod {

// A recording that cannot be read or written. what() names the file (and line) and the
// problem; code() is the matching positive errno (ENOENT, EINVAL, EEXIST, EIO, ...).
class RecordingError : public std::runtime_error {
  public:
    RecordingError(int code, const std::string& message) : std::runtime_error(message), code_(code)
    {
    }
    int code() const noexcept { return code_; }

  private:
    int code_;
};

// One pair of a recording.
struct RecordingEntry {
    uint64_t index = 0;        // `index` column, or the position in a plain folder
    int64_t left_stamp_ns = 0; // recorded capture times
    int64_t right_stamp_ns = 0;
    std::string left_path; // full paths (DIR joined with the row's names)
    std::string right_path;
};

struct Recording {
    std::string dir;
    bool has_index = false;              // true: read from frames.csv; false: a plain folder
    std::vector<RecordingEntry> entries; // in file (or name) order, never empty
    std::string calibration_path;        // DIR/calibration.yaml when it exists, else empty
    // Rows of frames.csv that were skipped, and why ("DIR/frames.csv:7: ..."). Only the
    // first kMaxProblems messages are kept; bad_rows counts them all.
    uint64_t bad_rows = 0;
    std::vector<std::string> problems;

    static constexpr std::size_t kMaxProblems = 20;
};

inline constexpr const char* kFramesCsvName = "frames.csv";
inline constexpr const char* kFramesCsvHeader = "index,left_stamp_ns,right_stamp_ns,left,right";
inline constexpr const char* kCalibrationName = "calibration.yaml";

// Reads `path` as a recording (when it holds frames.csv) or as a plain folder of
// left*/right* images whose stamps are k / nominal_fps seconds.
//
// Malformed rows of frames.csv are skipped and listed in `problems`; the recording fails
// only when the header is wrong or no row is usable. Images are not opened here: a
// missing or corrupt image is the replay's business (it skips the pair).
// Throws RecordingError: ENOENT for a missing directory or a folder without pairs,
// EINVAL for a bad header, no usable row, unequal left/right counts or fps <= 0.
Recording openRecording(const std::string& path, double nominal_fps);

// Writes pairs as a recording. Every pair's images are written completely first (each
// with one write() loop and a checked close()), then its row is appended to frames.csv
// with a single write(), so a process killed at any point leaves a readable recording of
// the pairs completed so far. No file is ever overwritten: images are created with
// O_EXCL. A failed write (ENOSPC, EDQUOT, EIO, ...) throws RecordingError with that errno
// and the file's name; the half-written image is removed and a half-written row cut off,
// so the recording stays readable up to the last complete pair.
//
// Thread-bound: one thread writes; the writer is not shared.
class RecordingWriter {
  public:
    // Creates `dir` (and left/, right/) and frames.csv with its header; copies
    // `calibration_path` in as calibration.yaml unless it is empty. Refuses a directory
    // that already holds a frames.csv (EEXIST). Throws RecordingError.
    explicit RecordingWriter(const std::string& dir, const std::string& calibration_path = {});
    ~RecordingWriter();

    RecordingWriter(const RecordingWriter&) = delete;
    RecordingWriter& operator=(const RecordingWriter&) = delete;

    // Appends one pair: two images of the same size (the size of the first pair), each
    // CV_8UC1 or CV_8UC3 BGR (a colour camera's: written as a colour PNG),
    // with their capture times. Returns the pair's index (0, 1, ...). Throws
    // RecordingError (EINVAL for a wrong image, EIO when writing fails); a failed pair
    // leaves no row behind.
    uint64_t write(const cv::Mat& left, const cv::Mat& right, int64_t left_stamp_ns,
                   int64_t right_stamp_ns);

    // Writes `yaml_text` as DIR/calibration.yaml (a calibration that came as text, e.g.
    // from the service). Refuses to replace one that is there (EEXIST). Throws
    // RecordingError.
    void writeCalibrationText(const std::string& yaml_text);

    uint64_t pairsWritten() const noexcept { return next_index_; }
    const std::string& directory() const noexcept { return dir_; }

  private:
    void writeImage(const std::string& relative_name, const cv::Mat& image);

    std::string dir_;
    std::string csv_path_;
    UniqueFd csv_fd_;        // frames.csv, O_APPEND
    uint64_t csv_bytes_ = 0; // its length after the last complete row
    cv::Size size_;          // size of the first pair; every pair must match
    uint64_t next_index_ = 0;
    std::vector<int> png_params_;
    std::vector<uchar> png_buffer_; // encoded image, reused from pair to pair
};

} // namespace stereod
