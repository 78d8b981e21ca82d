// `stereoctl calibrate --live --count N --board COLSxROWS --square-m S --out FILE`: chessboard
// stereo calibration from the running service's raw (unrectified) pairs (the `raw` stream
// of docs/protocol.md). Each pair is searched for the board (shrunk for the search,
// refined at full size); a pair with the board in both images is accepted unless it nearly
// repeats an accepted one (pipeline/calibration_coverage.hpp), and after each verdict the
// person holding the board is told what the accepted views still lack. Accepted pairs are
// saved as PNG at once, so that nothing is lost and the same calibration can be re-run
// offline; at N pairs (or at the timeout, or on Ctrl-C) the calibration is made exactly as
// the file-based form makes it (calibrateFromCorners, the same table, JSON and refusals).

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <system_error>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "base/name_table.hpp"
#include "ctl/calibration_report.hpp"
#include "ctl/client.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "ctl/output.hpp"
#include "ctl/payload.hpp"
#include "ctl/raw_pair.hpp"
#include "ctl/signal_catcher.hpp"
#include "pipeline/calibration_coverage.hpp"
#include "pipeline/chessboard_calibration.hpp"

namespace stereod {

namespace {

using json = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

// Reads the grey pair of a `raw` event into `pair`; its frame number. Throws ClientError
// naming the frame and the image that is missing, and as readRawPair does for a payload
// that does not add up or is cut short. Payloads this stereoctl does not know are read
// past: the calibration needs the grey pair only.
uint64_t readCalibrationPair(ProtocolClient& client, const json& event, RawPair& pair)
{
    const uint64_t frame = event.value("frame", uint64_t{0});
    const RawPairContents contents = readRawPair(client, event, pair, Results{});
    if (!contents.left || !contents.right) {
        throw ClientError(fmt::format("a raw event from {} (frame {}) lacks the {} u8_gray {}",
                                      client.socketPath(), frame,
                                      !contents.left && !contents.right ? "raw_left and raw_right"
                                      : !contents.left                  ? "raw_left"
                                                                        : "raw_right",
                                      !contents.left && !contents.right ? "payloads" : "payload"),
                          0);
    }
    return frame;
}

bool listed(const json& reply, const char* key, const char* value)
{
    const auto list = reply.find(key);
    return list != reply.end() && list->is_array() &&
           std::find(list->begin(), list->end(), json(value)) != list->end();
}

// Where accepted pairs go: --save-pairs, or beside --out ("rig.yaml" -> "rig-pairs/").
std::string pairsDirectory(const CalibrateOptions& options)
{
    if (!options.save_pairs_dir.empty()) {
        return options.save_pairs_dir;
    }
    const std::filesystem::path out(options.out_path);
    return (out.parent_path() / (out.stem().string() + "-pairs")).string();
}

// Creates the directory. One that already holds pairs is refused: the pairs of two runs
// would mix under the globs that re-run the calibration offline.
void preparePairsDirectory(const std::string& dir)
{
    std::error_code error;
    std::filesystem::create_directories(dir, error);
    if (error) {
        throw UsageError(fmt::format("--save-pairs: cannot create {}: {}", dir, error.message()));
    }
    for (std::filesystem::directory_iterator it(dir, error), end; !error && it != end;
         it.increment(error)) {
        const std::string name = it->path().filename().string();
        if ((name.starts_with("left_") || name.starts_with("right_")) && name.ends_with(".png")) {
            throw UsageError(fmt::format("--save-pairs: {} already holds pairs ({}): give a new "
                                         "or empty directory, so that two runs' pairs do not mix",
                                         dir, name));
        }
    }
    if (error) {
        throw UsageError(fmt::format("--save-pairs: cannot read {}: {}", dir, error.message()));
    }
}

enum class Stop { Count, Timeout, Interrupted };

inline constexpr NameTable<Stop, 3> kStops{{{
    {Stop::Count, "count"},
    {Stop::Timeout, "timeout"},
    {Stop::Interrupted, "interrupted"},
}}};
static_assert(kStops.wellFormed());

const char* stopName(Stop stop)
{
    return kStops.name(stop);
}

// The views of one run: the verdict on each raw pair, the accepted pairs (saved and
// reported), and what is said to the person holding the board.
//
// Thread-bound.
class LiveCollector {
  public:
    LiveCollector(const CalibrateOptions& options, const ChessboardCalibrationOptions& calibration,
                  std::string pairs_dir)
        : options_(options), grid_(calibration.board.cols, calibration.board.rows),
          pairs_dir_(std::move(pairs_dir)),
          name_digits_(std::max(3, static_cast<int>(std::to_string(options.count).size())))
    {
    }

    // Judges one raw pair (the service's frame `frame`); true once --count pairs are accepted.
    bool take(uint64_t frame, const RawPair& pair)
    {
        ++frames_;
        if (!coverage_) {
            image_size_ = pair.left.size();
            coverage_.emplace(image_size_, grid_);
        }
        if (pair.left.size() != image_size_ || pair.right.size() != image_size_) {
            throw ChessboardCalibrationError(fmt::format(
                "the service's raw frames changed size: {}x{} and {}x{} at frame {}, {}x{} before; "
                "a calibration holds for one resolution",
                pair.left.cols, pair.left.rows, pair.right.cols, pair.right.rows, frame,
                image_size_.width, image_size_.height));
        }
        const bool left_found = findBoardCornersFast(pair.left, grid_, left_corners_);
        const bool right_found = findBoardCornersFast(pair.right, grid_, right_corners_);
        if (!left_found || !right_found) {
            const char* where = left_found    ? "board not found in the right image"
                                : right_found ? "board not found in the left image"
                                              : "board not found";
            say(where, fmt::format("frame {}: {}", frame, where), false);
            return false;
        }
        ++board_in_both_;
        const ViewJudgement judgement = coverage_->judge(left_corners_, right_corners_);
        if (judgement.duplicate_of) {
            ++refused_;
            say("duplicate of " + std::to_string(*judgement.duplicate_of),
                fmt::format("frame {}: refused: {}", frame, judgement.reason), true);
            return false;
        }
        accept(frame, pair, judgement.view.left);
        return static_cast<int>(pairs_.size()) >= options_.count;
    }

    // The accepted pairs as the file-based calibration's input.
    std::vector<PairReport> takePairs() { return std::move(pairs_); }
    int accepted() const noexcept { return static_cast<int>(pairs_.size()); }
    cv::Size imageSize() const noexcept { return image_size_; }

    void printSummary(Stop stop, double seconds) const
    {
        const char* why = stop == Stop::Count     ? "done"
                          : stop == Stop::Timeout ? "timed out"
                                                  : "interrupted";
        fmt::print(stderr,
                   "live: {} after {:.1f} s with {} of {} pairs ({} pairs looked at, the board "
                   "in both images in {}, {} refused as near-duplicates); pairs saved in {}\n",
                   why, seconds, pairs_.size(), options_.count, frames_, board_in_both_, refused_,
                   pairs_dir_);
        if (coverage_) {
            fmt::print(stderr, "live: {}\n", formatGaps(coverage_->gaps()));
        }
        fmt::print(stderr,
                   "live: to calibrate again from these pairs: stereoctl calibrate --left "
                   "'{}/left_*.png' --right '{}/right_*.png' --board {} --square-m {} --out {}\n",
                   pairs_dir_, pairs_dir_, options_.board, *options_.square_m, options_.out_path);
        std::fflush(stderr);
    }

    json report(Stop stop, int skipped_by_service) const
    {
        json missing = json::object();
        if (coverage_) {
            const CoverageGaps gaps = coverage_->gaps();
            missing = {{"left_cells", gaps.left_cells},
                       {"right_cells", gaps.right_cells},
                       {"tilts", gaps.tilts},
                       {"distances", gaps.distances}};
        }
        return {{"live",
                 {{"socket", options_.service.socket_path},
                  {"count", options_.count},
                  {"accepted", pairs_.size()},
                  {"stopped", stopName(stop)},
                  {"pairs_seen", frames_},
                  {"pairs_skipped_by_service", skipped_by_service},
                  {"board_in_both", board_in_both_},
                  {"refused_duplicates", refused_},
                  {"pairs_dir", pairs_dir_},
                  {"coverage_missing", missing}}}};
    }

  private:
    void accept(uint64_t frame, const RawPair& pair, const BoardAppearance& left)
    {
        const int number = static_cast<int>(pairs_.size()) + 1;
        PairReport report;
        report.left_path = fmt::format("{}/left_{:0{}}.png", pairs_dir_, number, name_digits_);
        report.right_path = fmt::format("{}/right_{:0{}}.png", pairs_dir_, number, name_digits_);
        writeImagePng(report.left_path, pair.left);
        writeImagePng(report.right_path, pair.right);
        report.left_found = true;
        report.right_found = true;
        report.left_corners = left_corners_;
        report.right_corners = right_corners_;
        pairs_.push_back(std::move(report));
        coverage_->accept(left_corners_, right_corners_);
        say("accepted " + std::to_string(number),
            fmt::format("frame {}: accepted pair {}/{}: board at {:.0f} %, {:.0f} % of the left "
                        "image, {:.0f} % of its size, turned {:+.0f} (yaw) {:+.0f} (pitch) degrees",
                        frame, number, options_.count, 100.0 * left.centre_frac.x,
                        100.0 * left.centre_frac.y, 100.0 * left.size_frac, left.yaw_deg,
                        left.pitch_deg),
            true);
    }

    // Prints `line` on stderr when the verdict (`key`) differs from the last one: a person
    // holding the board still, or out of view, gets one line, not one per pair.
    // `with_gaps` adds a line of what the accepted views still lack.
    void say(const std::string& key, const std::string& line, bool with_gaps)
    {
        if (key == last_said_) {
            return;
        }
        last_said_ = key;
        fmt::print(stderr, "{}\n", line);
        if (with_gaps) {
            fmt::print(stderr, "  {}\n", formatGaps(coverage_->gaps()));
        }
        std::fflush(stderr);
    }

    const CalibrateOptions& options_;
    const cv::Size grid_;
    const std::string pairs_dir_;
    const int name_digits_;
    std::optional<CalibrationCoverage> coverage_; // made at the first pair (its size)
    cv::Size image_size_;
    std::vector<cv::Point2f> left_corners_;
    std::vector<cv::Point2f> right_corners_;
    std::vector<PairReport> pairs_;
    std::string last_said_;
    int frames_ = 0;
    int board_in_both_ = 0;
    int refused_ = 0;
};

} // namespace

int runLiveCalibration(const CalibrateOptions& options)
{
    const ChessboardCalibrationOptions calibration_options = chessboardOptions(options);
    if (options.count < calibration_options.min_pairs) {
        throw UsageError(fmt::format("--count {} is below --min-pairs {}: the calibration would "
                                     "refuse that few pairs",
                                     options.count, calibration_options.min_pairs));
    }
    if (!(options.max_hz > 0.0)) {
        throw UsageError(fmt::format("--max-hz must be > 0, got {}", options.max_hz));
    }
    const std::string pairs_dir = pairsDirectory(options);
    LiveCollector collector(options, calibration_options, pairs_dir);
    Stop stop = Stop::Count;
    int skipped_by_service = 0;
    const auto start = Clock::now();
    {
        SignalCatcher signals;
        ProtocolClient client(options.service.socket_path,
                              std::chrono::milliseconds(options.service.timeout_ms));
        client.setCancelFd(signals.fd());
        const json hello = client.request({{"cmd", "hello"}});
        if (!listed(hello, "streams", "raw")) {
            throw ServiceError("not_available",
                               "the service at " + options.service.socket_path +
                                   " offers no raw (unrectified) frames: its hello lists no "
                                   "\"raw\" stream; it is older than this stereoctl");
        }
        // Made only once the service is known to offer raw frames: a run that cannot start
        // leaves no empty directory behind.
        preparePairsDirectory(pairs_dir);
        client.request({{"cmd", "subscribe"}, {"stream", "raw"}, {"max_hz", options.max_hz}});
        fmt::print(stderr,
                   "live: collecting {} pairs with the {}x{} board in both images from {} "
                   "(up to {} pairs/s{}); Ctrl-C stops and calibrates with what there is\n",
                   options.count, calibration_options.board.cols, calibration_options.board.rows,
                   options.service.socket_path, options.max_hz,
                   options.timeout_s ? fmt::format(", for at most {} s", *options.timeout_s)
                                     : std::string());
        std::fflush(stderr);

        const std::optional<Clock::time_point> deadline =
            options.timeout_s
                ? std::optional(start + std::chrono::duration_cast<Clock::duration>(
                                            std::chrono::duration<double>(*options.timeout_s)))
                : std::nullopt;
        const std::chrono::milliseconds wait_limit(options.service.timeout_ms);
        RawPair pair;
        // Set while the wait in progress is the one the deadline cut short.
        std::optional<Clock::time_point> waiting_until;
        try {
            for (;;) {
                if (deadline) {
                    const auto left =
                        std::chrono::ceil<std::chrono::milliseconds>(*deadline - Clock::now());
                    if (left.count() <= 0) {
                        stop = Stop::Timeout;
                        break;
                    }
                    client.setTimeout(std::min(wait_limit, left));
                    waiting_until = left < wait_limit ? deadline : std::nullopt;
                }
                json event;
                try {
                    event = client.readJson();
                } catch (const ClientError&) {
                    // A wait the deadline cut short is the timeout the person asked for; a
                    // wait under the normal limit that ran out is a service gone quiet, and
                    // a connection lost before the deadline is an error either way.
                    if (waiting_until && Clock::now() >= *waiting_until) {
                        stop = Stop::Timeout;
                        break;
                    }
                    throw;
                }
                // The deadline bounds the wait for the next frame; a frame that has begun
                // arriving is read whole under the normal limit, never cut off by it.
                client.setTimeout(wait_limit);
                if (event.value("event", std::string()) != "raw") {
                    client.skipPayload(payloadBytes(event));
                    continue;
                }
                skipped_by_service += event.value("skipped", 0);
                const uint64_t frame = readCalibrationPair(client, event, pair);
                if (collector.take(frame, pair)) {
                    stop = Stop::Count;
                    break;
                }
                if (signals.pending()) {
                    stop = Stop::Interrupted;
                    break;
                }
            }
        } catch (const ClientCancelled&) {
            stop = Stop::Interrupted;
        }
    }
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    collector.printSummary(stop, seconds);
    if (collector.accepted() == 0) {
        throw ChessboardCalibrationError(fmt::format(
            "no pair accepted ({}): nothing to calibrate from; hold the whole board in view of "
            "both cameras",
            stop == Stop::Timeout ? "timed out" : "interrupted"));
    }
    const json live_report = collector.report(stop, skipped_by_service);
    const ChessboardCalibrationResult result =
        calibrateFromCorners(collector.takePairs(), collector.imageSize(), calibration_options);
    finishChessboardCalibration(result, options, live_report);
    return kExitOk;
}

} // namespace stereod
