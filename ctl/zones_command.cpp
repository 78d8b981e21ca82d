// `stereoctl zones`: the keep-out zones of the running service (docs/stereoctl.md).

#include <chrono>
#include <cstdio>
#include <string>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "ctl/client.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "ctl/signal_catcher.hpp"

namespace stereod {

namespace {

using json = nlohmann::ordered_json;

std::string zoneLine(const json& zone)
{
    std::string line = fmt::format("{}: {}", zone.value("name", std::string("?")),
                                   zone.value("state", std::string("unknown")));
    if (zone.contains("reason"))
        line += " (" + zone["reason"].get<std::string>() + ")";
    if (zone.value("points", 0) > 0 && zone.contains("nearest_point_m")) {
        const json& p = zone["nearest_point_m"];
        line += fmt::format(", nearest {:.3f} m at ({:.2f}, {:.2f}, {:.2f})",
                            zone.value("nearest_m", 0.0), p[0].get<double>(), p[1].get<double>(),
                            p[2].get<double>());
    }
    line += fmt::format(", {} points, {:.0f} % in sight", zone.value("points", 0),
                        100.0 * zone.value("visible_fraction", 0.0));
    return line;
}

// 1 when any zone is occupied; else 2 when any is unknown, none are configured, or the
// zones are older than allowed; else 0.
int exitCodeFor(const json& zones, bool stale)
{
    bool unknown = stale || !zones.is_array() || zones.empty();
    bool occupied = false;
    for (const json& zone : zones) {
        const std::string state = zone.value("state", std::string("unknown"));
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
