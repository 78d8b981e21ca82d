// The commands that talk to the running service: distance, status, watch, snapshot.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <spawn.h>
#include <unistd.h>

#include "ctl/client.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "ctl/output.hpp"
#include "ctl/payload.hpp"
#include "ctl/reading_format.hpp"
#include "ctl/signal_catcher.hpp"
#include "pipeline/depth_io.hpp"
#include "protocol/request.hpp"

extern char** environ;

namespace stereod {

namespace {

// A page only this user can read (in XDG_RUNTIME_DIR) that sends the browser on to `url`;
// `url` itself when there is no such directory or the file cannot be written.
std::string privateRedirect(const std::string& url)
{
    const char* runtime = std::getenv("XDG_RUNTIME_DIR");
    if (runtime == nullptr || *runtime == '\0')
        return url;
    std::string path = std::string(runtime) + "/stereod-view-XXXXXX.html";
    const int fd = ::mkstemps(path.data(), 5); // mode 0600
    if (fd < 0)
        return url;
    const std::string html = "<!DOCTYPE html><meta http-equiv=\"refresh\" content=\"0;url=" + url +
                             "\"><a href=\"" + url + "\">stereod live view</a>\n";
    const bool written = ::write(fd, html.data(), html.size()) == static_cast<ssize_t>(html.size());
    ::close(fd);
    return written ? "file://" + path : url;
}

using json = nlohmann::ordered_json;

ProtocolClient connect(const ConnectionOptions& options)
{
    return ProtocolClient(options.socket_path, std::chrono::milliseconds(options.timeout_ms));
}

// A field of a reply as text: fixed-point with `decimals`, "-" when missing.
std::string number(const json& object, const char* key, int decimals)
{
    if (!object.is_object()) {
        return "-";
    }
    const auto it = object.find(key);
    if (it == object.end() || !it->is_number()) {
        return "-";
    }
    return fmt::format("{:.{}f}", it->get<double>(), decimals);
}

std::string text(const json& object, const char* key)
{
    if (!object.is_object()) {
        return "-";
    }
    const auto it = object.find(key);
    if (it == object.end() || it->is_null()) {
        return "-";
    }
    return it->is_string() ? it->get<std::string>() : it->dump();
}

// A string field that may be absent or empty (an error text): "" unless it is a string.
std::string optionalText(const json& object, const char* key)
{
    if (!object.is_object()) {
        return {};
    }
    const auto it = object.find(key);
    return it != object.end() && it->is_string() ? it->get<std::string>() : std::string();
}

const json& member(const json& object, const char* key)
{
    static const json kNull;
    if (!object.is_object()) {
        return kNull;
    }
    const auto it = object.find(key);
    return it == object.end() ? kNull : *it;
}

void printCamera(const json& camera)
{
    std::string line = fmt::format(
        "  {:<8} {:<10} {:>6} {:>8} {:>8} {:>5} {:>8}", text(camera, "name"), text(camera, "state"),
        number(camera, "fps", 1), number(camera, "frames", 0), number(camera, "dropped", 0),
        number(camera, "bad_frames", 0), number(camera, "unpaired", 0));
    if (const std::string error = optionalText(camera, "last_error"); !error.empty()) {
        line += "  " + error;
    }
    fmt::print("{}\n", line);
}

void printStatus(const json& status)
{
    fmt::print("stereod: {}, up {} s\n", text(status, "state"), number(status, "uptime_s", 1));

    const json& source = member(status, "source");
    fmt::print("source: {}, {}\n", text(source, "kind"), text(source, "state"));
    if (const std::string reason = optionalText(source, "down_reason"); !reason.empty()) {
        fmt::print("  down: {}\n", reason);
    }
    if (const std::string error = optionalText(source, "last_error"); !error.empty()) {
        fmt::print("  last error: {}\n", error);
    }
    fmt::print("  {:<8} {:<10} {:>6} {:>8} {:>8} {:>5} {:>8}  {}\n", "camera", "state", "fps",
               "frames", "dropped", "bad", "unpaired", "last error");
    if (const json& cameras = member(source, "cameras"); cameras.is_array()) {
        for (const json& camera : cameras) {
            printCamera(camera);
        }
    }
    fmt::print("  pairs {}, dropped in the ring {}, dropped unpaired {}\n",
               number(source, "pairs", 0), number(source, "ring_dropped", 0),
               number(source, "unpaired_dropped", 0));
    const json& skew = member(source, "skew_ms");
    fmt::print("  pairing skew: mean {} ms, p99 {} ms, max {} ms\n", number(skew, "mean", 2),
               number(skew, "p99", 2), number(skew, "max", 2));
    if (const json& offset = member(source, "clock_offset");
        offset.is_object() && offset.value("detected", false)) {
        fmt::print("  clock offset between the cameras: right - left = {} ms (modulo the frame "
                   "period)\n",
                   number(offset, "estimate_ms", 2));
    }
    if (const json& warnings = member(source, "warnings"); warnings.is_array()) {
        for (const json& warning : warnings) {
            if (warning.is_string())
                fmt::print("  warning: {}\n", warning.get<std::string>());
        }
    }

    const json& pipeline = member(status, "pipeline");
    const json& extended = member(pipeline, "extended_range");
    fmt::print(
        "pipeline: {} frames, {} fps, matcher {}, {} disparities from {}{}, closest depth {} "
        "m, depth out to {} m\n",
        number(pipeline, "frames", 0), number(pipeline, "fps", 1), text(pipeline, "matcher"),
        number(pipeline, "num_disparities", 0), number(pipeline, "min_disparity", 0),
        extended.is_boolean() && extended.get<bool>() ? " and the extended range" : "",
        number(pipeline, "closest_depth_m", 2), number(pipeline, "max_output_depth_m", 1));
    printStageTable(stdout, member(pipeline, "stage_ms"));
    const json& latency = member(pipeline, "latency_ms");
    fmt::print("latency from capture to reading: p50 {} ms, p99 {} ms\n", number(latency, "p50", 1),
               number(latency, "p99", 1));
    const json& health = member(status, "calibration_health");
    if (health.is_object() && health.contains("state")) {
        const std::string reason = text(health, "reason");
        fmt::print("calibration health: {}{}", text(health, "state"),
                   reason.empty() ? std::string() : " (" + reason + ")");
        if (health.contains("max_row_error_px"))
            fmt::print(", rows up to {} px apart, {} px at the centre, roll {} deg ({} matches)",
                       number(health, "max_row_error_px", 2), number(health, "offset_px", 2),
                       number(health, "roll_deg", 3), number(health, "matches", 0));
        fmt::print("\n");
    }

    const json& calibration = member(status, "calibration");
    if (text(calibration, "kind") == "none") {
        fmt::print("calibration: none (uncalibrated: raw frames only, no distances)\n");
    } else {
        fmt::print("calibration: {}, f {} px, B {} m, doffs {} px, {}x{}, {}\n",
                   text(calibration, "kind"), number(calibration, "focal_px", 1),
                   number(calibration, "baseline_m", 3), number(calibration, "doffs_px", 1),
                   number(calibration, "width", 0), number(calibration, "height", 0),
                   text(calibration, "path"));
    }

    const json& clients = member(status, "clients");
    fmt::print("clients: {} connected, {} subscribed, {} frames dropped, {} disconnected as too "
               "slow\n",
               number(clients, "connected", 0), number(clients, "subscribers", 0),
               number(clients, "frames_dropped", 0), number(clients, "disconnected_slow", 0));

    const json& live = member(status, "live_view");
    if (live.is_object()) {
        if (live.value("listening", false)) {
            fmt::print("live view: http://{}/, {} clients, {} messages ({} MB), {} readings sent, "
                       "{} frames dropped for slow clients, {} clients closed as not reading\n",
                       text(live, "listen"), number(live, "clients", 0),
                       number(live, "messages_sent", 0),
                       live.value("bytes_sent", 0.0) > 0
                           ? fmt::format("{:.1f}", live.value("bytes_sent", 0.0) / 1e6)
                           : std::string("0"),
                       number(live, "readings_sent", 0), number(live, "frames_dropped", 0),
                       number(live, "clients_dropped", 0));
        } else {
            const std::string error = optionalText(live, "error");
            fmt::print("live view: {}{}\n",
                       text(live, "listen") == "off" ? std::string("off")
                                                     : "not listening on " + text(live, "listen"),
                       error.empty() ? std::string() : ": " + error);
        }
    }

    if (const json& reading = member(status, "reading"); reading.is_object()) {
        fmt::print("reading: {}\n", formatWatchLine(reading));
    }
}

} // namespace

int runDistance(const DistanceOptions& options)
{
    ProtocolClient client = connect(options.service);
    json request = {{"cmd", "distance"}};
    if (options.max_age_ms) {
        request["max_age_ms"] = *options.max_age_ms;
    }
    const json reply = client.request(request);
    const json& reading = member(reply, "reading");
    if (!reading.is_object()) {
        throw ClientError(
            "the distance reply from " + options.service.socket_path + " has no reading object", 0);
    }
    if (options.json) {
        fmt::print("{}\n", reading.dump());
    } else {
        fmt::print("{}\n", formatDistance(reading));
    }
    return exitCodeForReading(reading);
}

int runStatus(const StatusOptions& options)
{
    ProtocolClient client = connect(options.service);
    const json reply = client.request({{"cmd", "status"}});
    const json& status = member(reply, "status");
    if (options.json) {
        fmt::print("{}\n", status.dump(2));
    } else {
        printStatus(status);
    }
    return kExitOk;
}

int runView(const StatusOptions& options)
{
    ProtocolClient client = connect(options.service);
    const json reply = client.request({{"cmd", "view"}});
    const std::string listen = text(reply, "listen");
    if (!reply.value("listening", false)) {
        fmt::print(stderr, "stereoctl: the live view is not listening ({}){}\n",
                   listen.empty() || listen == "off" ? "live_view.listen: off"
                                                     : "live_view.listen: " + listen,
                   text(reply, "error").empty() ? "" : ": " + text(reply, "error"));
        return kExitNoReading;
    }
    const std::string page = text(reply, "page");
    fmt::print("{}\nFoxglove: Open connection, Foxglove WebSocket, {}\n", page,
               text(reply, "websocket"));
    const char* display = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    if ((display != nullptr && *display != '\0') || (wayland != nullptr && *wayland != '\0')) {
        // The browser gets a file of this user's that leads to the page, not the page's
        // address: a command line is visible to every user of the machine, the token in
        // it would be too.
        const std::string opened = privateRedirect(page);
        // Detached: the browser outlives this command.
        pid_t pid = 0;
        const char* argv[] = {"xdg-open", opened.c_str(), nullptr};
        if (posix_spawnp(&pid, "xdg-open", nullptr, nullptr, const_cast<char* const*>(argv),
                         environ) != 0)
            fmt::print(stderr, "stereoctl: no xdg-open to open a browser; open {} yourself\n",
                       page);
    }
    return kExitOk;
}

int runWatch(const WatchOptions& options)
{
    SignalCatcher signals;
    ProtocolClient client = connect(options.service);
    client.setCancelFd(signals.fd());
    try {
        client.request({{"cmd", "subscribe"}, {"stream", "readings"}});
        // Readings come as fast as frames do, or not at all while the source is down:
        // only the service going away ends the wait.
        client.setTimeout(ProtocolClient::kWaitForever);
        for (;;) {
            const json event = client.readJson();
            client.skipPayload(payloadBytes(event));
            if (event.value("event", std::string()) != "reading") {
                continue;
            }
            if (options.json) {
                fmt::print("{}\n", event.dump());
            } else {
                std::string line = formatWatchLine(member(event, "reading"));
                if (const auto skipped = event.value("skipped", 0); skipped > 0) {
                    line += fmt::format("  ({} skipped)", skipped);
                }
                fmt::print("{}\n", line);
            }
            // Each line must reach a pipe reader now, not when a buffer fills.
            std::fflush(stdout);
            if (signals.pending()) {
                return kExitOk;
            }
        }
    } catch (const ClientCancelled&) {
        return kExitOk;
    }
}

int runSnapshot(const SnapshotOptions& options)
{
    const bool want_depth = !options.depth_path.empty() || !options.colormap_path.empty();
    const bool want_disparity = !options.disparity_path.empty();
    const bool want_left = !options.left_path.empty();
    const bool want_cloud = !options.cloud_path.empty();
    const bool want_confidence = !options.confidence_path.empty();
    if (!want_depth && !want_disparity && !want_left && !want_cloud && !want_confidence) {
        throw UsageError("nothing to write: give at least one of --depth, --disparity, --cloud, "
                         "--colormap, --left, --confidence");
    }
    json items = json::array();
    if (want_depth) {
        items.push_back("depth");
    }
    if (want_disparity) {
        items.push_back("disparity");
    }
    if (want_left) {
        items.push_back("left");
    }
    if (want_cloud) {
        items.push_back("cloud");
    }
    if (want_confidence) {
        items.push_back("confidence");
    }

    ProtocolClient client = connect(options.service);
    // The colour beside the left image and the cloud, from a service that has it (an
    // older one would refuse the unknown items).
    const json hello = client.request({{"cmd", "hello"}});
    const auto offers = [&hello](const char* item) {
        const auto list = hello.find("snapshot_items");
        return list != hello.end() && list->is_array() &&
               std::find(list->begin(), list->end(), json(item)) != list->end();
    };
    if (want_left && offers("left_colour")) {
        items.push_back("left_colour");
    }
    if (want_cloud && offers("cloud_colour")) {
        items.push_back("cloud_colour");
    }
    const json reply = client.request({{"cmd", "snapshot"}, {"items", items}});
    const json& payloads = member(reply, "payloads");
    if (!payloads.is_array()) {
        throw ClientError(
            "the snapshot reply from " + options.service.socket_path + " has no payloads list", 0);
    }

    // Every payload is read off the socket before anything is written, so that a slow
    // disk does not hold the service's connection open longer than the transfer.
    cv::Mat depth_mm;
    cv::Mat disparity;
    cv::Mat left;
    cv::Mat left_colour;
    cv::Mat confidence;
    std::vector<CloudPoint> cloud;
    std::vector<CloudColour> cloud_colour;
    bool have_depth = false, have_disparity = false, have_left = false, have_cloud = false;
    bool have_confidence = false;
    for (const json& header : payloads) {
        const Payload payload = parsePayload(header);
        if (payload.name == snapshotItemName(SnapshotItem::Depth) &&
            payload.format == kFormatDepthMm) {
            readImagePayload(client, payload, CV_16UC1, depth_mm);
            have_depth = true;
        } else if (payload.name == snapshotItemName(SnapshotItem::Disparity) &&
                   payload.format == kFormatDisparityPx) {
            readImagePayload(client, payload, CV_32FC1, disparity);
            have_disparity = true;
        } else if (payload.name == snapshotItemName(SnapshotItem::Left) &&
                   payload.format == kFormatGray) {
            readImagePayload(client, payload, CV_8UC1, left);
            have_left = true;
        } else if (payload.name == snapshotItemName(SnapshotItem::LeftColour) &&
                   payload.format == kFormatRgb) {
            readColourPayload(client, payload, left_colour);
        } else if (payload.name == snapshotItemName(SnapshotItem::CloudColour) &&
                   payload.format == kFormatRgb) {
            readCloudColourPayload(client, payload, cloud_colour);
        } else if (payload.name == snapshotItemName(SnapshotItem::Confidence) &&
                   payload.format == kFormatConfidence) {
            readImagePayload(client, payload, CV_8UC1, confidence);
            have_confidence = true;
        } else if (payload.name == snapshotItemName(SnapshotItem::Cloud) &&
                   payload.format == kFormatCloud) {
            readCloudPayload(client, payload, cloud);
            have_cloud = true;
        } else {
            // A payload this client does not know (a newer service): read past it.
            client.skipPayload(payload.bytes);
        }
    }
    const auto require = [&](bool wanted, bool have, const char* name) {
        if (wanted && !have) {
            throw ClientError(std::string("the snapshot from ") + options.service.socket_path +
                                  " has no " + name + " payload",
                              0);
        }
    };
    require(want_depth, have_depth, "depth");
    require(want_disparity, have_disparity, "disparity");
    require(want_left, have_left, "left");
    require(want_cloud, have_cloud, "cloud");
    require(want_confidence, have_confidence, "confidence");

    const std::string frame = number(reply, "frame", 0);
    if (want_depth) {
        cv::Mat depth_m;
        depth_mm.convertTo(depth_m, CV_32FC1, 1e-3); // 0 (invalid) stays 0
        if (!options.depth_path.empty()) {
            writeDepthPng(options.depth_path, depth_m);
            fmt::print("wrote depth {} ({}x{}, frame {})\n", options.depth_path, depth_m.cols,
                       depth_m.rows, frame);
        }
        if (!options.colormap_path.empty()) {
            const auto [near_m, far_m] = depthDisplayRange(depth_m);
            writeColorizedDepth(options.colormap_path, depth_m, near_m, far_m);
            fmt::print("wrote colormap {} ({:.2f} m to {:.2f} m, frame {})\n",
                       options.colormap_path, near_m, far_m, frame);
        }
    }
    if (want_disparity) {
        writeDisparity(options.disparity_path, disparity);
        fmt::print("wrote disparity {} ({}x{}, frame {})\n", options.disparity_path, disparity.cols,
                   disparity.rows, frame);
    }
    if (want_left) {
        // In colour where the camera kept it, else the grey the matcher saw.
        const bool colour = !left_colour.empty() && left_colour.size() == left.size();
        writeImagePng(options.left_path, colour ? left_colour : left);
        fmt::print("wrote left {} ({}x{}{}, frame {})\n", options.left_path, left.cols, left.rows,
                   colour ? ", colour" : "", frame);
    }
    if (want_cloud) {
        // Coloured where every point has its colour.
        if (cloud_colour.size() != cloud.size()) {
            cloud_colour.clear();
        }
        writePly(options.cloud_path, cloud, cloud_colour);
        fmt::print("wrote cloud {} ({} points{}, frame {})\n", options.cloud_path, cloud.size(),
                   cloud_colour.empty() ? "" : ", coloured", frame);
    }
    if (want_confidence) {
        writeConfidencePng(options.confidence_path, confidence);
        fmt::print("wrote confidence {} ({}x{}, frame {})\n", options.confidence_path,
                   confidence.cols, confidence.rows, frame);
    }
    return kExitOk;
}

} // namespace stereod
