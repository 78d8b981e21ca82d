// `stereoctl record`: the service's raw pairs (the `raw` stream of docs/protocol.md) written
// as a recording that the replay source plays back: a CSV+PNG directory
// (replay/recording.hpp), or, when --out ends in `.mcap`, a ROS 2 bag
// (replay/mcap_recording.hpp) with the calibration in force as camera_info and, with
// --with depth,points, each pair's depth and point cloud (the raw stream `with` them: one
// event holds a pair and its results, so they cannot be mismatched). A pair with colour
// gets a coloured cloud, its `rgb` packed by ros2::xyziRgbCloud() as the ROS 2 publisher
// packs it.
//
// Two threads: this one reads the stream off the socket (ctl/record_events.hpp) into a
// bounded pool of pair buffers; a writer thread (ctl/record_queue.hpp) encodes and writes
// them with RecordingWriter. When every buffer
// is full (the disk is slower than the cameras), the pair is read past and counted as
// dropped: the socket is always drained, so the service never holds a backlog for us
// (and its own backlog bound protects its worker anyway).

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <system_error>
#include <vector>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <unistd.h>

#include "base/name_table.hpp"
#include "ctl/client.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "ctl/payload.hpp"
#include "ctl/record_events.hpp"
#include "ctl/record_queue.hpp"
#include "ctl/signal_catcher.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/calibration_formats.hpp"
#include "protocol/request.hpp"
#include "replay/mcap_recording.hpp"
#include "replay/recording.hpp"
#include "ros2/conventions.hpp"

namespace stereod {

namespace {

using json = nlohmann::ordered_json;
namespace fs = std::filesystem;

// A new directory, or an existing empty one: a user's data is never overwritten.
void checkOutputDirectory(const std::string& dir)
{
    std::error_code error;
    const fs::file_status status = fs::symlink_status(dir, error);
    if (error && error != std::errc::no_such_file_or_directory) {
        throw UsageError("cannot check --out " + dir + ": " + error.message());
    }
    if (!fs::exists(status)) {
        return;
    }
    if (!fs::is_directory(status)) {
        throw UsageError("refusing --out " + dir + ": it exists and is not a directory");
    }
    if (!fs::is_empty(dir, error) || error) {
        throw UsageError("refusing --out " + dir +
                         ": the directory is not empty (a recording is never written over "
                         "existing files; choose a new directory)");
    }
}

bool isMcapPath(const std::string& path)
{
    return path.size() > 5 && path.compare(path.size() - 5, 5, ".mcap") == 0;
}

// A new file in an existing directory: a user's bag is never overwritten.
void checkOutputFile(const std::string& path)
{
    std::error_code error;
    if (fs::exists(fs::symlink_status(path, error))) {
        throw UsageError("refusing --out " + path +
                         ": it exists (a recording is never written "
                         "over an existing file; choose a new name)");
    }
    const fs::path parent = fs::path(path).parent_path();
    if (!parent.empty() && !fs::is_directory(parent, error)) {
        throw UsageError("cannot write --out " + path + ": " + parent.string() +
                         " is not a directory");
    }
}

// Why the recording ended.
enum class Ending { Frames, Signal, ServiceGone, WriteFailed };

inline constexpr NameTable<Ending, 4> kEndings{{{
    {Ending::Frames, "frames"},
    {Ending::Signal, "signal"},
    {Ending::ServiceGone, "service_gone"},
    {Ending::WriteFailed, "write_failed"},
}}};
static_assert(kEndings.wellFormed());

const char* endingName(Ending ending)
{
    return kEndings.name(ending, "frames");
}

struct Counts {
    uint64_t received = 0;        // pairs read whole off the socket into a buffer
    uint64_t service_skipped = 0; // the events' "skipped": pairs the service did not send us
    uint64_t queue_dropped = 0;   // pairs read past because every buffer was full
};

// The progress line: on a terminal rewritten in place every second, else a line every
// five seconds (a log).
class Progress {
  public:
    Progress() : terminal_(::isatty(STDERR_FILENO) == 1) {}

    void update(const Counts& counts, uint64_t written, std::size_t queued, std::size_t capacity,
                bool final_line)
    {
        const auto now = std::chrono::steady_clock::now();
        const auto interval = terminal_ ? std::chrono::seconds(1) : std::chrono::seconds(5);
        if (!final_line && now - last_ < interval) {
            return;
        }
        last_ = now;
        const std::string line = fmt::format(
            "recording: {} pairs written, {} received, {} dropped ({} by the service, {} queue "
            "full), queue {}/{}",
            written, counts.received, counts.service_skipped + counts.queue_dropped,
            counts.service_skipped, counts.queue_dropped, queued, capacity);
        if (terminal_) {
            fmt::print(stderr, "\r{}\033[K{}", line, final_line ? "\n" : "");
        } else {
            fmt::print(stderr, "{}\n", line);
        }
        std::fflush(stderr);
    }

  private:
    bool terminal_;
    std::chrono::steady_clock::time_point last_{};
};

// Whether the service sends the cameras' colour with raw pairs (`with` colour): its hello
// lists the raw colour items.
bool serviceSendsColour(ProtocolClient& client)
{
    const json hello = client.request({{"cmd", "hello"}});
    const auto items = hello.find("snapshot_items");
    return items != hello.end() && items->is_array() &&
           std::find(items->begin(), items->end(),
                     json(snapshotItemName(SnapshotItem::RawLeftColour))) != items->end();
}

// The calibration in force in the service, as file text; empty when it runs uncalibrated.
std::string serviceCalibration(ProtocolClient& client)
{
    try {
        const json reply = client.request({{"cmd", "calibration"}});
        if (!reply.value("calibrated", false)) {
            return {};
        }
        return reply.value("text", std::string());
    } catch (const ServiceError& error) {
        // A service older than the `calibration` request, or one whose calibration did not
        // come from a file: record without it, and say so.
        fmt::print(stderr, "stereoctl: recording without calibration.yaml: {}\n", error.what());
        return {};
    }
}

} // namespace

int runRecord(const RecordOptions& options)
{
    if (options.queue_pairs == 0) {
        throw UsageError("--queue must be at least 1 pair");
    }
    const Results results = parseWith(options.with);
    const bool mcap = isMcapPath(options.out_dir);
    if (results.any() && !mcap) {
        throw UsageError("--with needs --out FILE.mcap: a CSV+PNG recording holds raw pairs only");
    }
    if (mcap) {
        checkOutputFile(options.out_dir);
    } else {
        checkOutputDirectory(options.out_dir);
    }
    SignalCatcher signals;
    ProtocolClient client(options.service.socket_path,
                          std::chrono::milliseconds(options.service.timeout_ms));
    client.setCancelFd(signals.fd());

    const std::string calibration_text = serviceCalibration(client);
    if (results.any() && calibration_text.empty()) {
        throw UsageError("--with: the service makes no depth or points without a calibration "
                         "file in force; record without --with");
    }
    bool calibration_written = false; // calibration.yaml, or camera_info in the bag
    std::optional<RecordingWriter> csv;
    std::optional<McapRecordingWriter> bag;
    PairWriter::WriteFn write;
    if (mcap) {
        try {
            bag.emplace(options.out_dir);
        } catch (const mcap::McapError& e) {
            throw UsageError(e.what());
        }
        if (!calibration_text.empty()) {
            // The calibration in force as camera_info beside every pair (ROS convention:
            // the right camera's P[3] = -fx' * baseline).
            try {
                const auto [left, right] = rosCameraInfoPair(
                    parseCalibration(calibration_text, "the service's calibration"));
                bag->setCameraInfo(cameraInfoMessage(left), cameraInfoMessage(right));
                calibration_written = true;
            } catch (const CalibrationError& error) {
                // E.g. 12 or 14 distortion coefficients: no ROS distortion model holds them.
                fmt::print(stderr, "stereoctl: the bag has no camera_info: {}\n", error.what());
            }
        } else {
            fmt::print(stderr, "stereoctl: the service runs uncalibrated: the bag has no "
                               "camera_info\n");
        }
        if (results.depth)
            bag->enableDepth();
        if (results.points)
            bag->enablePoints();
        // The pairs in the one time base (CLOCK_REALTIME, as ROS stamps its messages): log
        // times that never step back when the service replays a recording in a loop, and
        // stamps that merge with the robot's other data. A pair's depth and points carry
        // its left image's stamp: the depth is the left camera's view, and a ROS user
        // pairs them with the image by stamp.
        // `xyzirgb`: the coloured cloud's points interleaved, capacity kept (writer thread).
        write = [&bag, results, xyzirgb = std::vector<float>()](const RawPair& p) mutable {
            const int64_t left = p.left_realtime_ns.value_or(p.left_stamp_ns);
            const int64_t right = p.right_realtime_ns.value_or(p.right_stamp_ns);
            bag->write(p.left_colour.empty() ? p.left : p.left_colour,
                       p.right_colour.empty() ? p.right : p.right_colour, left, right);
            if (results.depth && p.depth_present)
                bag->writeDepth(p.depth_m, left);
            if (!results.points || !p.cloud_present)
                return;
            if (!p.left_colour.empty() && p.cloud_colour.size() == p.cloud.size()) {
                ros2::xyziRgbCloud(p.cloud, p.cloud_colour, xyzirgb);
                bag->writeColouredPoints(xyzirgb.data(), p.cloud.size(), left);
            } else {
                bag->writePoints(reinterpret_cast<const float*>(p.cloud.data()), p.cloud.size(),
                                 left);
            }
        };
    } else {
        csv.emplace(options.out_dir);
        if (!calibration_text.empty()) {
            csv->writeCalibrationText(calibration_text);
            calibration_written = true;
        } else {
            fmt::print(stderr, "stereoctl: the service runs uncalibrated: the recording has no "
                               "calibration.yaml\n");
        }
        write = [&csv](const RawPair& p) {
            csv->write(p.left_colour.empty() ? p.left : p.left_colour,
                       p.right_colour.empty() ? p.right : p.right_colour, p.left_stamp_ns,
                       p.right_stamp_ns);
        };
    }

    PairQueue queue(options.queue_pairs);
    PairWriter pair_writer(write, queue);
    Counts counts;
    Progress progress;
    Ending ending = Ending::Frames;
    std::string gone_reason;

    try {
        json subscribe = {{"cmd", "subscribe"}, {"stream", "raw"}};
        json with = json::array();
        if (results.depth)
            with.push_back(snapshotItemName(SnapshotItem::Depth));
        if (results.points)
            with.push_back(snapshotItemName(SnapshotItem::Cloud));
        // The cameras' colour, recorded as captured, from a service that sends it (an
        // older one would refuse the name).
        if (serviceSendsColour(client))
            with.push_back("colour");
        if (!with.empty())
            subscribe["with"] = std::move(with);
        client.request(subscribe);
        bool results_checked = !results.any();
        // Pairs come as fast as the cameras deliver, or not at all while the source is
        // down: only the service going away, a signal or the disk ends the wait.
        client.setTimeout(ProtocolClient::kWaitForever);
        while (!options.frames || counts.received < *options.frames) {
            if (pair_writer.failed()) {
                ending = Ending::WriteFailed;
                break;
            }
            if (signals.pending()) {
                ending = Ending::Signal;
                break;
            }
            const json event = client.readJson();
            if (event.value("event", std::string()) != "raw") {
                client.skipPayload(payloadBytes(event));
                continue;
            }
            if (!results_checked) {
                checkResultsPresent(event, results, client.socketPath());
                results_checked = true;
            }
            counts.service_skipped += event.value("skipped", uint64_t{0});
            const std::optional<std::size_t> slot = queue.takeFree();
            if (!slot) {
                skipRawPair(client, event);
                ++counts.queue_dropped;
            } else if (readRawPair(client, event, queue.buffer(*slot), results).complete()) {
                queue.push(*slot);
                ++counts.received;
            } else {
                // A pair this stereoctl cannot record whole is not recorded.
                queue.giveBack(*slot);
            }
            progress.update(counts, pair_writer.written(), queue.queued(), queue.capacity(), false);
        }
    } catch (const ClientCancelled&) {
        ending = Ending::Signal;
    } catch (const ClientError& error) {
        ending = Ending::ServiceGone;
        gone_reason = error.what();
    }
    // Whatever ended it, what was received is written out and the recording closed.
    queue.close();
    pair_writer.join();
    if (pair_writer.failed()) {
        ending = Ending::WriteFailed;
    }
    std::string close_error;
    if (bag) {
        // The summary and footer: what lets readers seek. A bag that misses them (a
        // failed write, a kill) still replays up to its last complete chunk.
        try {
            bag->close();
        } catch (const mcap::McapError& e) {
            close_error = e.what();
            ending = Ending::WriteFailed;
        }
    }
    progress.update(counts, pair_writer.written(), 0, queue.capacity(), true);

    // A bag's pairs count once their chunk is on disk: a chunk the disk refused (ENOSPC,
    // EFBIG) holds pairs handed to the writer that no replay will find.
    const uint64_t written = bag ? bag->pairsOnDisk() : pair_writer.written();
    const std::string write_error = pair_writer.failed() ? pair_writer.error() : close_error;
    const uint64_t dropped = counts.service_skipped + counts.queue_dropped;
    if (options.json) {
        // A bag is a file, a CSV+PNG recording a directory: the key says which.
        json summary = {{mcap ? "file" : "dir", options.out_dir},
                        {"pairs", written},
                        {"dropped", dropped},
                        {"service_skipped", counts.service_skipped},
                        {"queue_dropped", counts.queue_dropped},
                        {"calibration", calibration_written},
                        {"ended", endingName(ending)}};
        if (ending == Ending::WriteFailed) {
            summary["error"] = write_error;
        } else if (ending == Ending::ServiceGone) {
            summary["error"] = gone_reason;
        }
        fmt::print("{}\n", summary.dump());
    } else {
        fmt::print("recorded {} pairs to {} ({} dropped: {} skipped by the service, {} with the "
                   "queue full)\n",
                   written, options.out_dir, dropped, counts.service_skipped, counts.queue_dropped);
    }
    switch (ending) {
    case Ending::WriteFailed:
        fmt::print(stderr, "stereoctl: recording stopped: {}\n", write_error);
        return kExitUsage;
    case Ending::ServiceGone:
        fmt::print(stderr, "stereoctl: recording ended, the service went away: {}\n", gone_reason);
        return kExitUnreachable;
    case Ending::Frames:
    case Ending::Signal:
        break;
    }
    return kExitOk;
}

} // namespace stereod
