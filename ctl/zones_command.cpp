// `stereoctl zones`: the keep-out zones of the running service (docs/stereoctl.md).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "ctl/client.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "ctl/output.hpp"
#include "ctl/payload.hpp"
#include "ctl/signal_catcher.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/depth_io.hpp"
#include "pipeline/zones.hpp"
#include "protocol/request.hpp"

namespace stereod {

namespace {

using json = nlohmann::ordered_json;

// A field as text: a number with `decimals`, text as it is, "?" for anything else (null,
// missing): a zone's state must reach the user and the exit code whatever its numbers say.
std::string field(const json& zone, const char* key, int decimals = 3, double scale = 1.0)
{
    const auto it = zone.find(key);
    if (it == zone.end() || it->is_null())
        return "?";
    if (it->is_number())
        return fmt::format("{:.{}f}", it->get<double>() * scale, decimals);
    return it->is_string() ? it->get<std::string>() : it->dump();
}

std::string zoneLine(const json& zone)
{
    std::string line = fmt::format("{}: {}", field(zone, "name"), field(zone, "state"));
    if (zone.contains("reason"))
        line += " (" + field(zone, "reason") + ")";
    const auto points = zone.find("points");
    const bool has_points =
        points != zone.end() && points->is_number() && points->get<double>() > 0;
    if (has_points && zone.contains("nearest_point_m")) {
        const json& p = zone["nearest_point_m"];
        std::string at = "?";
        if (p.is_array() && p.size() == 3 &&
            std::all_of(p.begin(), p.end(), [](const json& v) { return v.is_number(); }))
            at = fmt::format("({:.2f}, {:.2f}, {:.2f})", p[0].get<double>(), p[1].get<double>(),
                             p[2].get<double>());
        line += ", nearest " + field(zone, "nearest_m") + " m at " + at;
    }
    line += ", " + field(zone, "points", 0) + " points, " +
            field(zone, "visible_fraction", 0, 100.0) + " % in sight";
    return line;
}

// 1 when any zone is occupied; else 2 when any is unknown, none are configured, or the
// zones are older than allowed; else 0.
int exitCodeFor(const json& zones, bool stale)
{
    bool unknown = stale || !zones.is_array() || zones.empty();
    bool occupied = false;
    for (const json& zone : zones) {
        const auto it = zone.find("state");
        const std::string state =
            it != zone.end() && it->is_string() ? it->get<std::string>() : "unknown";
        occupied = occupied || state == "occupied";
        unknown = unknown || state == "unknown";
    }
    if (occupied)
        return kExitNoReading;
    return unknown ? kExitNotProducing : kExitOk;
}

void print(const json& frame, const json& zones, bool stale, double age_ms)
{
    if (!zones.is_array() || zones.empty()) {
        fmt::print("no keep-out zones configured (zones in the service configuration)\n");
        return;
    }
    fmt::print("frame {}, {:.0f} ms old{}\n", frame.is_null() ? std::string("-") : frame.dump(),
               age_ms, stale ? " (stale: older than allowed, states unknown)" : "");
    for (const json& zone : zones)
        fmt::print("  {}\n", zoneLine(zone));
}

cv::Vec3d vec3(const json& value)
{
    if (!value.is_array() || value.size() != 3)
        return {0, 0, 0};
    return {value[0].get<double>(), value[1].get<double>(), value[2].get<double>()};
}

// The depth as grey, near bright and far dark (inverse depth between the display range's
// ends, as colorizeDepth() spreads it), black where there is none: a background on which
// the zones' colours are the only colours.
cv::Mat greyDepth(const cv::Mat& depth_m, double near_m, double far_m)
{
    const double inv_far = 1.0 / far_m;
    const double inv_near = 1.0 / near_m;
    cv::Mat grey(depth_m.size(), CV_8UC1);
    for (int y = 0; y < depth_m.rows; ++y) {
        const float* z = depth_m.ptr<float>(y);
        uint8_t* out = grey.ptr<uint8_t>(y);
        for (int x = 0; x < depth_m.cols; ++x) {
            const bool ok = z[x] > 0.0f && std::isfinite(z[x]);
            const double t =
                ok ? std::clamp((1.0 / z[x] - inv_far) / (inv_near - inv_far), 0.0, 1.0) : 0.0;
            // 40..200: the far end stays apart from "no depth", the near end from white.
            out[x] = ok ? static_cast<uint8_t>(std::lround(40.0 + 160.0 * t)) : 0;
        }
    }
    cv::Mat picture;
    cv::cvtColor(grey, picture, cv::COLOR_GRAY2BGR);
    return picture;
}

// The zones of `reply` drawn on the depth of the latest frame in grey: each box's twelve
// edges projected into the rectified left image (parts behind the camera left out), red
// occupied, green clear, yellow unknown, with a label (name, state, points, share in
// sight) on a box of the zone's colour.
void drawPicture(ProtocolClient& client, const json& reply, const std::string& path)
{
    const json camera = reply.value("camera", json::object());
    if (!camera.contains("focal_px"))
        throw UsageError("--picture: the service runs uncalibrated: no depth to draw on");
    const json snapshot = client.request({{"cmd", "snapshot"}, {"items", json::array({"depth"})}});
    cv::Mat depth_mm;
    for (const json& header : snapshot.value("payloads", json::array())) {
        const Payload payload = parsePayload(header);
        if (payload.name == snapshotItemName(SnapshotItem::Depth) &&
            payload.format == kFormatDepthMm)
            readImagePayload(client, payload, CV_16UC1, depth_mm);
        else
            client.skipPayload(payload.bytes);
    }
    if (depth_mm.empty())
        throw ClientError("the snapshot has no depth payload", 0);
    cv::Mat depth_m;
    depth_mm.convertTo(depth_m, CV_32FC1, 1e-3);
    const auto [near_m, far_m] = depthDisplayRange(depth_m);
    cv::Mat picture = greyDepth(depth_m, near_m, far_m);
    // Labels readable at any image size: about 1.6 % of the width high.
    const double font_scale = std::max(0.45, picture.cols / 1400.0);
    const int font_thickness = picture.cols >= 1000 ? 2 : 1;

    const json pose = reply.value("camera_pose", json::object());
    const CameraPose camera_pose{toVec3(vec3(pose.value("translation_m", json()))),
                                 toVec3(vec3(pose.value("rpy_deg", json())))};
    const cv::Matx33d base_to_optical = opticalToBaseRotation(camera_pose).t();
    const double f = camera["focal_px"].get<double>();
    const double cx = camera["cx_px"].get<double>();
    struct Label {
        std::string text;
        cv::Point corner; // the box's top left in the picture
        cv::Scalar colour, ink;
    };
    std::vector<Label> labels;
    const double cy = camera["cy_px"].get<double>();
    constexpr double kNearPlane = 0.05; // m: edges are cut where they pass behind this
    const auto optical = [&](const cv::Vec3d& base) {
        return base_to_optical * (base - toCv(camera_pose.translation_m));
    };
    const auto pixel = [&](const cv::Vec3d& p) {
        return cv::Point2d(f * p[0] / p[2] + cx, f * p[1] / p[2] + cy);
    };
    for (const json& zone : reply.value("zones", json::array())) {
        const std::string state = zone.value("state", std::string("unknown"));
        const cv::Scalar colour = state == "occupied" ? cv::Scalar(40, 40, 230)
                                  : state == "clear"  ? cv::Scalar(60, 200, 60)
                                                      : cv::Scalar(40, 220, 230);
        const cv::Vec3d lo = vec3(zone.value("min_m", json()));
        const cv::Vec3d hi = vec3(zone.value("max_m", json()));
        cv::Vec3d corners[8];
        for (int i = 0; i < 8; ++i)
            corners[i] = optical(
                {(i & 1) ? hi[0] : lo[0], (i & 2) ? hi[1] : lo[1], (i & 4) ? hi[2] : lo[2]});
        cv::Point label(picture.cols, picture.rows);
        bool in_view = false; // a label only for a zone the picture shows
        const cv::Rect2d image(0, 0, picture.cols, picture.rows);
        for (int a = 0; a < 8; ++a)
            for (int bit = 1; bit < 8; bit <<= 1) {
                const int b = a | bit;
                if (b == a)
                    continue;
                cv::Vec3d p = corners[a], q = corners[b];
                if (p[2] < kNearPlane && q[2] < kNearPlane)
                    continue;
                // Cut the edge where it passes behind the near plane.
                if (p[2] < kNearPlane)
                    p = q + (p - q) * ((q[2] - kNearPlane) / (q[2] - p[2]));
                if (q[2] < kNearPlane)
                    q = p + (q - p) * ((p[2] - kNearPlane) / (p[2] - q[2]));
                const cv::Point2d from = pixel(p), to = pixel(q);
                cv::line(picture, from, to, colour, 2, cv::LINE_AA);
                in_view = in_view || image.contains(from) || image.contains(to);
                label.x = std::min(label.x, static_cast<int>(std::min(from.x, to.x)));
                label.y = std::min(label.y, static_cast<int>(std::min(from.y, to.y)));
            }
        if (in_view) {
            // Black on green and yellow, white on red.
            labels.push_back(
                {fmt::format("{}: {}, {} points, {:.0f} % in sight",
                             zone.value("name", std::string()), state, zone.value("points", 0),
                             100.0 * zone.value("visible_fraction", 0.0)),
                 label, colour,
                 state == "occupied" ? cv::Scalar(255, 255, 255) : cv::Scalar(0, 0, 0)});
        }
    }
    // The labels after every box, so that no edge crosses one; each above its box's top
    // left corner, kept inside the picture, and moved down past the labels already placed
    // where two would overlap.
    std::vector<cv::Rect> placed;
    for (const Label& l : labels) {
        int baseline = 0;
        const cv::Size size = cv::getTextSize(l.text, cv::FONT_HERSHEY_SIMPLEX, font_scale,
                                              font_thickness, &baseline);
        const int pad = 3;
        cv::Rect box(std::clamp(l.corner.x, 0, std::max(0, picture.cols - size.width - 2 * pad)),
                     std::max(0, l.corner.y - 4 - size.height - pad), size.width + 2 * pad,
                     size.height + baseline + 2 * pad);
        for (bool moved = true; moved;) {
            moved = false;
            for (const cv::Rect& other : placed) {
                if ((box & other).area() > 0) {
                    box.y = other.y + other.height + 1;
                    moved = true;
                }
            }
        }
        box.y = std::min(box.y, std::max(0, picture.rows - box.height));
        placed.push_back(box);
        cv::rectangle(picture, box, l.colour, cv::FILLED);
        cv::putText(picture, l.text, cv::Point(box.x + pad, box.y + pad + size.height),
                    cv::FONT_HERSHEY_SIMPLEX, font_scale, l.ink, font_thickness, cv::LINE_AA);
    }
    writeImagePng(path, picture);
}

} // namespace

int runZones(const ZonesOptions& options)
{
    ProtocolClient client(options.service.socket_path,
                          std::chrono::milliseconds(options.service.timeout_ms));
    if (!options.watch) {
        const json reply = client.request({{"cmd", "zones"}});
        const json zones = reply.value("zones", json::array());
        const double age_ms = reply.value("age_ms", 0.0);
        const bool stale = reply.value("frame", json()).is_null() || age_ms > options.max_age_ms;
        if (options.json)
            fmt::print("{}\n", reply.dump(2));
        else
            print(reply.value("frame", json()), zones, stale, age_ms);
        if (!options.picture_path.empty()) {
            drawPicture(client, reply, options.picture_path);
            if (!options.json)
                fmt::print("wrote {}\n", options.picture_path);
        }
        return exitCodeFor(zones, stale);
    }
    SignalCatcher signals;
    client.setCancelFd(signals.fd());
    try {
        client.request({{"cmd", "subscribe"}, {"stream", "zones"}});
        client.setTimeout(ProtocolClient::kWaitForever);
        for (;;) {
            const json event = client.readJson();
            if (event.value("event", std::string()) != "zones")
                continue;
            if (options.json)
                fmt::print("{}\n", event.dump());
            else
                print(event.value("frame", json()), event.value("zones", json::array()), false,
                      event.value("age_ms", 0.0));
            std::fflush(stdout);
            if (signals.pending())
                return kExitOk;
        }
    } catch (const ClientCancelled&) {
        return kExitOk;
    }
}

} // namespace stereod
