#include "replay/recording.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <system_error>

#include <fcntl.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <unistd.h>

#include "base/system_error.hpp"

namespace stereod {

namespace fs = std::filesystem;

namespace {

std::string_view trim(std::string_view text)
{
    const auto is_space = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
    while (!text.empty() && is_space(text.front()))
        text.remove_prefix(1);
    while (!text.empty() && is_space(text.back()))
        text.remove_suffix(1);
    return text;
}

template <typename Int> bool parseInteger(std::string_view text, Int& out)
{
    if (text.empty())
        return false;
    const char* end = text.data() + text.size();
    const auto [ptr, ec] = std::from_chars(text.data(), end, out);
    return ec == std::errc() && ptr == end;
}

// One row of frames.csv, or the reason it cannot be used.
bool parseRow(std::string_view line, const fs::path& dir, RecordingEntry& entry,
              std::string& problem)
{
    std::string_view fields[5];
    std::size_t count = 0;
    std::size_t start = 0;
    for (;;) {
        const std::size_t comma = line.find(',', start);
        const std::string_view field = trim(line.substr(
            start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
        if (count < 5)
            fields[count] = field;
        ++count;
        if (comma == std::string_view::npos)
            break;
        start = comma + 1;
    }
    if (count != 5) {
        problem = "expected 5 fields (" + std::string(kFramesCsvHeader) + "), got " +
                  std::to_string(count);
        return false;
    }
    if (!parseInteger(fields[0], entry.index)) {
        problem = "index '" + std::string(fields[0]) + "' is not a non-negative integer";
        return false;
    }
    if (!parseInteger(fields[1], entry.left_stamp_ns)) {
        problem = "left_stamp_ns '" + std::string(fields[1]) + "' is not an integer";
        return false;
    }
    if (!parseInteger(fields[2], entry.right_stamp_ns)) {
        problem = "right_stamp_ns '" + std::string(fields[2]) + "' is not an integer";
        return false;
    }
    for (int side = 0; side < 2; ++side) {
        const std::string_view name = fields[3 + side];
        const char* column = side == 0 ? "left" : "right";
        if (name.empty()) {
            problem = std::string(column) + " file name is empty";
            return false;
        }
        if (fs::path(name).is_absolute()) {
            problem = std::string(column) + " file name '" + std::string(name) +
                      "' is absolute; names are relative to the recording";
            return false;
        }
        (side == 0 ? entry.left_path : entry.right_path) = (dir / fs::path(name)).string();
    }
    return true;
}

Recording readFramesCsv(const fs::path& dir, const fs::path& csv_path)
{
    const std::string csv_name = csv_path.string();
    std::ifstream in(csv_path);
    if (!in)
        throw RecordingError(errno != 0 ? errno : EIO,
                             csv_name + ": cannot open: " + errnoText(errno != 0 ? errno : EIO));

    Recording recording;
    recording.dir = dir.string();
    recording.has_index = true;

    std::string line;
    if (!std::getline(in, line))
        throw RecordingError(EINVAL, csv_name + ":1: empty file, expected the header '" +
                                         std::string(kFramesCsvHeader) + "'");
    std::string_view header = trim(line);
    if (header.substr(0, 3) == "\xEF\xBB\xBF") // a UTF-8 byte-order mark from an editor
        header.remove_prefix(3);
    if (header != kFramesCsvHeader)
        throw RecordingError(EINVAL, csv_name + ":1: header is '" + std::string(header) +
                                         "', expected '" + std::string(kFramesCsvHeader) + "'");

    uint64_t line_number = 1;
    while (std::getline(in, line)) {
        ++line_number;
        if (trim(line).empty())
            continue;
        // The recorder ends every row with a newline: a last row without one was cut
        // short by a killed process (or written by hand).
        const bool unterminated = in.eof();
        RecordingEntry entry;
        std::string problem;
        if (parseRow(line, dir, entry, problem)) {
            recording.entries.push_back(std::move(entry));
            continue;
        }
        ++recording.bad_rows;
        if (recording.problems.size() < Recording::kMaxProblems) {
            recording.problems.push_back(
                csv_name + ":" + std::to_string(line_number) + ": " + problem +
                (unterminated ? " (last row has no line end: recording cut short?)" : ""));
        }
    }
    if (in.bad())
        throw RecordingError(EIO, csv_name + ": read error: " + errnoText(EIO));

    if (recording.entries.empty()) {
        std::string message = csv_name + ": no usable row";
        if (recording.bad_rows > 0)
            message += " (" + std::to_string(recording.bad_rows) +
                       " malformed; first: " + recording.problems.front() + ")";
        throw RecordingError(EINVAL, message);
    }
    return recording;
}

bool hasImageExtension(const fs::path& file)
{
    std::string ext = file.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    static constexpr std::string_view kImageExtensions[] = {
        ".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".pnm", ".tif", ".tiff", ".webp"};
    return std::find(std::begin(kImageExtensions), std::end(kImageExtensions), ext) !=
           std::end(kImageExtensions);
}

bool startsWithNoCase(std::string_view text, std::string_view prefix)
{
    if (text.size() < prefix.size())
        return false;
    for (std::size_t i = 0; i < prefix.size(); ++i) {
        if (std::tolower(static_cast<unsigned char>(text[i])) != prefix[i])
            return false;
    }
    return true;
}

// Name order with runs of digits compared as numbers, so left2 comes before left10
// (and left002 before left010, as plain order would also give).
bool naturalLess(const std::string& a, const std::string& b)
{
    std::size_t i = 0;
    std::size_t j = 0;
    while (i < a.size() && j < b.size()) {
        const bool a_digit = std::isdigit(static_cast<unsigned char>(a[i])) != 0;
        const bool b_digit = std::isdigit(static_cast<unsigned char>(b[j])) != 0;
        if (a_digit && b_digit) {
            std::size_t i_end = i;
            std::size_t j_end = j;
            while (i_end < a.size() && std::isdigit(static_cast<unsigned char>(a[i_end])) != 0)
                ++i_end;
            while (j_end < b.size() && std::isdigit(static_cast<unsigned char>(b[j_end])) != 0)
                ++j_end;
            // Compare the numbers without their leading zeros: longer is larger.
            std::string_view x(a.data() + i, i_end - i);
            std::string_view y(b.data() + j, j_end - j);
            x.remove_prefix(std::min(x.find_first_not_of('0'), x.size()));
            y.remove_prefix(std::min(y.find_first_not_of('0'), y.size()));
            if (x.size() != y.size())
                return x.size() < y.size();
            if (x != y)
                return x < y;
            i = i_end;
            j = j_end;
            continue;
        }
        if (a[i] != b[j])
            return a[i] < b[j];
        ++i;
        ++j;
    }
    if ((a.size() - i) != (b.size() - j))
        return (a.size() - i) < (b.size() - j);
    return a < b; // equal as numbers (left1 / left01): any fixed order will do
}

Recording scanPairFolder(const fs::path& dir, double nominal_fps)
{
    const std::string dir_name = dir.string();
    if (!std::isfinite(nominal_fps) || nominal_fps <= 0.0)
        throw RecordingError(EINVAL, dir_name + ": no " + kFramesCsvName +
                                         ", and the nominal frame rate for a folder of "
                                         "left*/right* images must be > 0 (got " +
                                         std::to_string(nominal_fps) + ")");

    std::vector<std::string> lefts;
    std::vector<std::string> rights;
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        if (!it->is_regular_file(ec) || !hasImageExtension(it->path()))
            continue;
        const std::string name = it->path().filename().string();
        if (startsWithNoCase(name, "left"))
            lefts.push_back(name);
        else if (startsWithNoCase(name, "right"))
            rights.push_back(name);
    }
    if (ec)
        throw RecordingError(ec.value(), dir_name + ": cannot list: " + ec.message());
    if (lefts.empty() && rights.empty())
        throw RecordingError(ENOENT,
                             dir_name + ": neither " + kFramesCsvName + " nor left*/right* images");
    if (lefts.size() != rights.size())
        throw RecordingError(EINVAL, dir_name + ": " + std::to_string(lefts.size()) +
                                         " left* images but " + std::to_string(rights.size()) +
                                         " right* images; they pair by order, so the "
                                         "counts must match");
    std::sort(lefts.begin(), lefts.end(), naturalLess);
    std::sort(rights.begin(), rights.end(), naturalLess);

    Recording recording;
    recording.dir = dir_name;
    recording.has_index = false;
    recording.entries.resize(lefts.size());
    const double period_ns = 1e9 / nominal_fps;
    for (std::size_t i = 0; i < lefts.size(); ++i) {
        RecordingEntry& entry = recording.entries[i];
        entry.index = i;
        entry.left_stamp_ns = std::llround(static_cast<double>(i) * period_ns);
        entry.right_stamp_ns = entry.left_stamp_ns;
        entry.left_path = (dir / lefts[i]).string();
        entry.right_path = (dir / rights[i]).string();
    }
    return recording;
}

// Writes all of `size` bytes to `fd`; false with errno set when a write fails.
bool writeAll(int fd, const void* data, std::size_t size)
{
    const auto* bytes = static_cast<const char*>(data);
    while (size > 0) {
        const ssize_t written = ::write(fd, bytes, size);
        if (written < 0) {
            if (errno == EINTR)
                continue;
            return false;
        }
        if (written == 0) {
            errno = EIO;
            return false;
        }
        bytes += written;
        size -= static_cast<std::size_t>(written);
    }
    return true;
}

// Creates `path` (never replacing a file) with `size` bytes. On failure the partial file
// is removed and RecordingError carries the errno and the file's name.
void writeNewFile(const std::string& path, const void* data, std::size_t size)
{
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) {
        const int error = errno;
        throw RecordingError(error, path + ": cannot create: " + errnoText(error));
    }
    bool ok = writeAll(fd, data, size);
    int error = ok ? 0 : errno;
    // close() reports errors of writes the file system deferred (NFS, quotas).
    if (::close(fd) != 0 && ok) {
        ok = false;
        error = errno;
    }
    if (!ok) {
        ::unlink(path.c_str());
        throw RecordingError(error, path + ": cannot write: " + errnoText(error));
    }
}

} // namespace

Recording openRecording(const std::string& path, double nominal_fps)
{
    const fs::path dir(path);
    std::error_code ec;
    const fs::file_status status = fs::status(dir, ec);
    if (ec || !fs::exists(status)) {
        const int code = ec ? ec.value() : ENOENT;
        throw RecordingError(code, path + ": " + errnoText(code));
    }
    if (!fs::is_directory(status))
        throw RecordingError(ENOTDIR,
                             path + ": " + errnoText(ENOTDIR) + " (a recording is a directory)");

    const fs::path csv_path = dir / kFramesCsvName;
    Recording recording =
        fs::exists(csv_path, ec) ? readFramesCsv(dir, csv_path) : scanPairFolder(dir, nominal_fps);
    const fs::path calibration = dir / kCalibrationName;
    if (fs::is_regular_file(calibration, ec))
        recording.calibration_path = calibration.string();
    return recording;
}

RecordingWriter::RecordingWriter(const std::string& dir, const std::string& calibration_path)
    // PNG compression level 1: fast, because recording runs live.
    : dir_(dir),
      csv_path_((fs::path(dir) / kFramesCsvName).string()), png_params_{cv::IMWRITE_PNG_COMPRESSION,
                                                                        1}
{
    const fs::path root(dir);
    std::error_code ec;
    if (fs::exists(csv_path_, ec))
        throw RecordingError(EEXIST, csv_path_ + ": a recording is already there; "
                                                 "choose a new directory");
    for (const fs::path& sub : {root, root / "left", root / "right"}) {
        fs::create_directories(sub, ec);
        if (ec)
            throw RecordingError(ec.value(), sub.string() + ": cannot create: " + ec.message());
    }
    if (!calibration_path.empty()) {
        const fs::path target = root / kCalibrationName;
        fs::copy_file(calibration_path, target, fs::copy_options::overwrite_existing, ec);
        if (ec)
            throw RecordingError(ec.value(), "cannot copy calibration " + calibration_path +
                                                 " to " + target.string() + ": " + ec.message());
    }
    csv_fd_.reset(
        ::open(csv_path_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_APPEND | O_CLOEXEC, 0644));
    if (!csv_fd_.valid()) {
        const int error = errno;
        throw RecordingError(error, csv_path_ + ": cannot create: " + errnoText(error));
    }
    const std::string header = std::string(kFramesCsvHeader) + '\n';
    if (!writeAll(csv_fd_.get(), header.data(), header.size())) {
        const int error = errno;
        csv_fd_.reset();
        throw RecordingError(error, csv_path_ + ": cannot write: " + errnoText(error));
    }
    csv_bytes_ = header.size();
}

RecordingWriter::~RecordingWriter() = default;

void RecordingWriter::writeCalibrationText(const std::string& yaml_text)
{
    const std::string path = (fs::path(dir_) / kCalibrationName).string();
    writeNewFile(path, yaml_text.data(), yaml_text.size());
}

void RecordingWriter::writeImage(const std::string& relative_name, const cv::Mat& image)
{
    const std::string path = (fs::path(dir_) / relative_name).string();
    bool encoded = false;
    std::string reason = "the PNG encoder refused it";
    try {
        encoded = cv::imencode(".png", image, png_buffer_, png_params_);
    } catch (const cv::Exception& e) {
        reason = e.what();
    }
    if (!encoded)
        throw RecordingError(EINVAL, path + ": cannot encode: " + reason);
    writeNewFile(path, png_buffer_.data(), png_buffer_.size());
}

uint64_t RecordingWriter::write(const cv::Mat& left, const cv::Mat& right, int64_t left_stamp_ns,
                                int64_t right_stamp_ns)
{
    const auto eightBit = [](const cv::Mat& image) {
        return image.type() == CV_8UC1 || image.type() == CV_8UC3;
    };
    if (left.empty() || right.empty() || !eightBit(left) || !eightBit(right))
        throw RecordingError(EINVAL, dir_ + ": pair " + std::to_string(next_index_) +
                                         ": images must be non-empty 8-bit grey (CV_8UC1) or "
                                         "BGR colour (CV_8UC3)");
    if (left.size() != right.size())
        throw RecordingError(EINVAL, dir_ + ": pair " + std::to_string(next_index_) + ": left " +
                                         std::to_string(left.cols) + "x" +
                                         std::to_string(left.rows) + " and right " +
                                         std::to_string(right.cols) + "x" +
                                         std::to_string(right.rows) + " differ in size");
    if (next_index_ > 0 && left.size() != size_)
        throw RecordingError(EINVAL, dir_ + ": pair " + std::to_string(next_index_) + " is " +
                                         std::to_string(left.cols) + "x" +
                                         std::to_string(left.rows) + ", the recording is " +
                                         std::to_string(size_.width) + "x" +
                                         std::to_string(size_.height));

    char name[32];
    std::snprintf(name, sizeof name, "%06llu.png", static_cast<unsigned long long>(next_index_));
    const std::string left_name = std::string("left/") + name;
    const std::string right_name = std::string("right/") + name;
    writeImage(left_name, left);
    try {
        writeImage(right_name, right);
    } catch (const RecordingError&) {
        ::unlink((fs::path(dir_) / left_name).c_str());
        throw;
    }

    // One row, one write(): a killed process never leaves half a row behind. A write that
    // fails part way (a full disk) is cut back to the last complete row.
    const std::string row = std::to_string(next_index_) + ',' + std::to_string(left_stamp_ns) +
                            ',' + std::to_string(right_stamp_ns) + ',' + left_name + ',' +
                            right_name + '\n';
    if (!writeAll(csv_fd_.get(), row.data(), row.size())) {
        const int error = errno;
        [[maybe_unused]] const int cut = ::ftruncate(csv_fd_.get(), static_cast<off_t>(csv_bytes_));
        ::unlink((fs::path(dir_) / left_name).c_str());
        ::unlink((fs::path(dir_) / right_name).c_str());
        throw RecordingError(error, csv_path_ + ": cannot append pair " +
                                        std::to_string(next_index_) + ": " + errnoText(error));
    }
    csv_bytes_ += row.size();
    if (next_index_ == 0)
        size_ = left.size();
    return next_index_++;
}

} // namespace stereod
