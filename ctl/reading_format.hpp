#pragma once
// The reading object of the protocol (docs/protocol.md, "The reading object") as
// `stereoctl` prints it and decides its exit code from it. (The object itself is built by
// the protocol library, protocol/reading_json.hpp, for the service and `stereoctl depth`
// alike.)
//
// Reentrant: pure functions.

#include <optional>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "model/reading.hpp"

namespace stereod {

// The reason named by a protocol code ("too_few_valid_pixels", ...); nullopt when the
// code is unknown (a newer service).
std::optional<NoReadingReason> reasonFromCode(std::string_view code);

// Exit code of `stereoctl distance` for a reading object: 0 valid; 1 a fresh frame whose
// data support no number (too few valid pixels, nothing in range, bad frame); 2 the
// service is not producing (stale, out of sync, source down, no frame yet, or a reason
// this client does not know); 4 valid, but with `calibration_suspect`.
int exitCodeForReading(const nlohmann::ordered_json& reading);

// Whether the reading carries `calibration_suspect: true`.
bool calibrationSuspect(const nlohmann::ordered_json& reading);

// "LEFT EDGE: 11 % of the region cannot see this near": the note of a reading whose region
// the image's left edge keeps, in part, from seeing as near as its distance.
std::string leftEdgeNote(double out_of_view_fraction);

// "0.873 m", "0.873 m  CALIBRATION SUSPECT: rows +1.52 px apart" when the reading is
// flagged, "0.264 m  LEFT EDGE: 11 % of the region cannot see this near" when part of the
// region cannot see as near (out_of_view_fraction), or "no reading: <reason message>".
std::string formatDistance(const nlohmann::ordered_json& reading);

// One line of `stereoctl watch`: "frame 118  1.412 m  age 37 ms  valid 83 %", or the
// reason instead of the distance; flagged readings end with "  CALIBRATION SUSPECT: ...",
// and those with part of the region short of the distance with "  LEFT EDGE: ...".
std::string formatWatchLine(const nlohmann::ordered_json& reading);

} // namespace stereod
