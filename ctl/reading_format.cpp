#include "ctl/reading_format.hpp"

#include <array>
#include <cmath>

#include <fmt/format.h>

#include "ctl/exit_codes.hpp"

namespace stereod {

namespace {

bool isValid(const nlohmann::ordered_json& reading)
{
    const auto valid = reading.find("valid");
    const auto distance = reading.find("distance_m");
    return valid != reading.end() && valid->is_boolean() && valid->get<bool>() &&
           distance != reading.end() && distance->is_number();
}

// The reason's message, or its code, or a fallback when the service sent neither.
std::string reasonMessage(const nlohmann::ordered_json& reading)
{
    const auto reason = reading.find("reason");
    if (reason == reading.end() || !reason->is_object()) {
        return "the service gave no reason";
    }
    if (const auto message = reason->find("message");
        message != reason->end() && message->is_string()) {
        return message->get<std::string>();
    }
    if (const auto code = reason->find("code"); code != reason->end() && code->is_string()) {
        return code->get<std::string>();
    }
    return "the service gave no reason";
}

} // namespace

std::optional<NoReadingReason> reasonFromCode(std::string_view code)
{
    return kReasonCodes.parse(code);
}

bool calibrationSuspect(const nlohmann::ordered_json& reading)
{
    const auto suspect = reading.find("calibration_suspect");
    return suspect != reading.end() && suspect->is_boolean() && suspect->get<bool>();
}

int exitCodeForReading(const nlohmann::ordered_json& reading)
{
    if (isValid(reading)) {
        return calibrationSuspect(reading) ? kExitCalibrationSuspect : kExitOk;
    }
    std::optional<NoReadingReason> reason;
    if (const auto r = reading.find("reason"); r != reading.end() && r->is_object()) {
        if (const auto code = r->find("code"); code != r->end() && code->is_string()) {
            reason = reasonFromCode(code->get<std::string>());
        }
    }
    // A reason this client does not know cannot be vouched for as "fresh data without a
    // number": treat it as the service not producing.
    if (!reason || meansNotProducing(*reason) || *reason == NoReadingReason::None) {
        return kExitNotProducing;
    }
    return kExitNoReading;
}

namespace {

// "  CALIBRATION SUSPECT: rows +1.52 px apart" for a flagged reading, else "".
std::string suspectNote(const nlohmann::ordered_json& reading)
{
    if (!calibrationSuspect(reading)) {
        return {};
    }
    std::string note = "  CALIBRATION SUSPECT";
    if (const auto offset = reading.find("calibration_row_offset_px");
        offset != reading.end() && offset->is_number()) {
        note += fmt::format(": rows {:+.2f} px apart", offset->get<double>());
    }
    return note;
}

// "  LEFT EDGE: 11 % of the region cannot see this near" when the image's left edge cuts
// the view of part of the region short of the distance, else "".
std::string outOfViewNote(const nlohmann::ordered_json& reading)
{
    const auto share = reading.find("out_of_view_fraction");
    if (share == reading.end() || !share->is_number() || !(share->get<double>() > 0.0)) {
        return {};
    }
    return "  " + leftEdgeNote(share->get<double>());
}

// The notes a valid reading carries, at the end of its line.
std::string notes(const nlohmann::ordered_json& reading)
{
    return isValid(reading) ? suspectNote(reading) + outOfViewNote(reading) : std::string();
}

} // namespace

namespace {

// "0.873 m" or "no reading: <reason message>", without the flag.
std::string distanceText(const nlohmann::ordered_json& reading)
{
    if (isValid(reading)) {
        return fmt::format("{:.3f} m", reading["distance_m"].get<double>());
    }
    return "no reading: " + reasonMessage(reading);
}

} // namespace

std::string leftEdgeNote(double out_of_view_fraction)
{
    return fmt::format("LEFT EDGE: {:.0f} % of the region cannot see this near",
                       100.0 * out_of_view_fraction);
}

std::string formatDistance(const nlohmann::ordered_json& reading)
{
    return distanceText(reading) + notes(reading);
}

std::string formatWatchLine(const nlohmann::ordered_json& reading)
{
    std::string line;
    if (const auto frame = reading.find("frame"); frame != reading.end() && frame->is_number()) {
        line = fmt::format("frame {}  ", frame->get<uint64_t>());
    }
    line += distanceText(reading);
    if (const auto age = reading.find("age_ms"); age != reading.end() && age->is_number()) {
        line += fmt::format("  age {:.0f} ms", age->get<double>());
    }
    if (const auto valid = reading.find("valid_fraction");
        valid != reading.end() && valid->is_number()) {
        line += fmt::format("  valid {:.0f} %", 100.0 * valid->get<double>());
    }
    // At the end, where a reader scanning the columns finds them.
    return line + notes(reading);
}

} // namespace stereod
