#pragma once
// Exit codes of `stereoctl` (docs/stereoctl.md). Scripts and robots branch on them.

namespace stereod {

inline constexpr int kExitOk = 0;
// The data of a fresh frame support no distance (too few valid pixels, nothing in range,
// a bad frame); the output says why.
inline constexpr int kExitNoReading = 1;
// The reading is stale or the service is not producing; or the service refused the
// request. Shares its value with kExitUsage, as the command-line contract says.
inline constexpr int kExitNotProducing = 2;
// Bad arguments, unreadable input files, unwritable output files.
inline constexpr int kExitUsage = 2;
// The service cannot be reached (no socket, refused, connection lost, timed out).
inline constexpr int kExitUnreachable = 3;
// A distance, but the service suspects its calibration (`calibration_suspect`: its health
// check finds the rows of the two images apart): the number may be wrong.
inline constexpr int kExitCalibrationSuspect = 4;

} // namespace stereod
