#pragma once
// The reading object of the socket protocol (docs/protocol.md, "The reading object") and
// the zones the reading comes with, written by the service for every reply and event that
// carries them, and by `stereoctl depth --json`, so that both print the very same object.
//
// Reentrant: every function here is pure or writes only into the caller's buffer.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "model/reading.hpp"
#include "model/zone_reading.hpp"
#include "protocol/reply.hpp"

namespace stereod {

// What a reading object is written from.
struct ReadingReport {
    Reading reading;
    // False when no pair lies behind the reading (no frame yet, or a source that failed
    // before its first pair): stamp_ns and age_ms are left out.
    bool has_frame = true;
    // What only the party that saw it knows, appended to the reason's sentence: why a
    // frame was bad (its sizes, the error), why the source is down. Borrowed: the text
    // must outlive the report's use.
    std::string_view detail;
    // CLOCK_REALTIME minus CLOCK_MONOTONIC for the pair behind the reading
    // (PublishedFrame::realtime_offset_ns): with it the object carries stamp_realtime_ns.
    // None where no service clock lies behind the stamp (`stereoctl depth`).
    std::optional<int64_t> realtime_offset_ns;
};

// The reason of a reading as one sentence with the numbers the reading holds, e.g. "too
// few valid pixels in the region: 2.0 % valid, 10.0 % needed", and the detail after a
// colon when there is one. Empty for a valid reading.
std::string reasonMessage(const Reading& reading, std::string_view detail = {});

// Appends the reading object of docs/protocol.md; age_ms is `now_ns` minus the stamp.
// Allocates nothing once `out` has the capacity.
void appendReadingJson(std::string& out, const ReadingReport& report, int64_t now_ns);

// The same object, for composing replies.
Json readingToJson(const ReadingReport& report, int64_t now_ns);

// The zones of a frame as a JSON array of objects (name, state, reason, points,
// nearest_m, nearest_point_m, visible_fraction). Allocates nothing once `out` has the
// capacity.
void appendZonesJson(std::string& out, const std::vector<ZoneReading>& zones);

// The camera's pose on the robot: {"translation_m":[x,y,z],"rpy_deg":[r,p,y]}.
void appendCameraPoseJson(std::string& out, const CameraPose& pose);

} // namespace stereod
