#include "daemon/source_counter_watch.hpp"

#include <algorithm>

#include <fmt/format.h>

namespace stereod {

SourceCounterWatch::SourceCounterWatch(int64_t interval_ns) noexcept : interval_ns_(interval_ns) {}

bool SourceCounterWatch::due(int64_t now_ns) const noexcept
{
    return !looked_ || now_ns - last_look_ns_ >= interval_ns_;
}

namespace {

// How much `now` grew over `before`; a counter that went down (the source was replaced)
// counts from zero again.
uint64_t growth(uint64_t now, uint64_t before) noexcept
{
    return now >= before ? now - before : now;
}

std::string plural(uint64_t count, const char* one, const char* many)
{
    return fmt::format("{} {}", count, count == 1 ? one : many);
}

} // namespace

std::vector<SourceCounterWatch::Report> SourceCounterWatch::look(const SourceStatus& status,
                                                                 int64_t now_ns)
{
    std::vector<Report> reports;
    const double seconds = looked_ ? static_cast<double>(now_ns - last_look_ns_) / 1e9 : 0.0;
    std::vector<Counts> counts;
    counts.reserve(status.cameras.size());
    for (const CameraStatus& camera : status.cameras) {
        Counts now{camera.name, camera.bad_frames, camera.dropped, camera.unpaired};
        const auto before = std::find_if(last_.begin(), last_.end(),
                                         [&](const Counts& c) { return c.name == camera.name; });
        const Counts zero{};
        const Counts& base = before != last_.end() ? *before : zero;
        const uint64_t bad = growth(now.bad_frames, base.bad_frames);
        const uint64_t dropped = growth(now.dropped, base.dropped);
        const uint64_t unpaired = growth(now.unpaired, base.unpaired);
        counts.push_back(std::move(now));
        if (bad == 0 && dropped == 0 && unpaired == 0)
            continue;

        std::vector<std::string> parts;
        if (bad > 0) {
            std::string part = plural(bad, "bad frame", "bad frames");
            if (!camera.last_bad_frame.empty())
                part += " (latest: " + camera.last_bad_frame + ")";
            parts.push_back(std::move(part));
        }
        if (dropped > 0)
            parts.push_back(plural(dropped, "frame dropped", "frames dropped"));
        if (unpaired > 0)
            parts.push_back(plural(unpaired, "frame unpaired", "frames unpaired"));
        std::string line = fmt::format("camera {}: {}", camera.name, fmt::join(parts, ", "));
        line += looked_ ? fmt::format(" in the last {:.1f} s", seconds) : " since the start";
        reports.push_back({std::move(line), bad > 0});
    }
    last_ = std::move(counts);
    last_look_ns_ = now_ns;
    looked_ = true;
    return reports;
}

} // namespace stereod
