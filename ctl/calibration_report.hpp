#pragma once
// What the two chessboard forms of `stereoctl calibrate` share (from image files, and
// --live from the running service): the calibration options from the command line, and
// the end of a run: the calibration file, the preview, the per-pair table or the JSON.
//
// Reentrant: no state.

#include <nlohmann/json.hpp>

#include "ctl/commands.hpp"
#include "pipeline/chessboard_calibration.hpp"

namespace stereod {

// --board, --square-m, --alpha, --min-pairs as calibration options, validated. Throws
// UsageError for a malformed --board, std::invalid_argument for values the calibration
// refuses.
ChessboardCalibrationOptions chessboardOptions(const CalibrateOptions& options);

// Writes the calibration to --out and the preview (if asked), then prints the per-pair
// table and the summary, or with --json the report object. `extra_json` (an object, may
// be empty) is added to the report object: what a form knows beyond the calibration.
void finishChessboardCalibration(const ChessboardCalibrationResult& result,
                                 const CalibrateOptions& options,
                                 const nlohmann::ordered_json& extra_json);

} // namespace stereod
