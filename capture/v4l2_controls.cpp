// V4l2Device's controls: exposure, gain, white balance and anti-flicker, applied and
// read back in the units the settings use.
#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fmt/format.h>
#include <libv4l2.h>

#include "base/system_error.hpp"
#include "capture/v4l2_device.hpp"

namespace stereod {

int V4l2Device::queryControl(uint32_t id, v4l2_queryctrl& query)
{
    query = v4l2_queryctrl{};
    query.id = id;
    if (const int rc = xioctl(VIDIOC_QUERYCTRL, &query); rc < 0)
        return rc;
    if ((query.flags & V4L2_CTRL_FLAG_DISABLED) != 0)
        return -EINVAL;
    return 0;
}

ControlReading V4l2Device::readControl(const char* name, uint32_t id, int64_t unit)
{
    ControlReading reading;
    reading.name = name;
    reading.id = id;
    v4l2_queryctrl query{};
    if (queryControl(id, query) < 0)
        return reading;
    reading.present = true;
    v4l2_control control{};
    control.id = id;
    if (const int rc = xioctl(VIDIOC_G_CTRL, &control); rc < 0)
        reading.error = fmt::format("VIDIOC_G_CTRL: {}", errnoText(-rc));
    else
        reading.actual_value = static_cast<int64_t>(control.value) * unit;
    return reading;
}

ControlReading V4l2Device::setControl(const char* name, uint32_t id, int64_t value, int64_t unit)
{
    ControlReading reading;
    reading.name = name;
    reading.id = id;
    reading.requested = true;
    reading.requested_value = value;
    v4l2_queryctrl query{};
    if (queryControl(id, query) < 0) {
        reading.error = "not offered by the device";
        return reading;
    }
    reading.present = true;

    // Values in the unit of `name` (exposure in us) become device units (100 us).
    int64_t raw = (value + unit / 2) / unit;
    if (query.type == V4L2_CTRL_TYPE_INTEGER || query.type == V4L2_CTRL_TYPE_BOOLEAN) {
        const int64_t step = std::max<int64_t>(query.step, 1);
        const int64_t clamped =
            query.minimum +
            (std::clamp<int64_t>(raw, query.minimum, query.maximum) - query.minimum) / step * step;
        if (clamped != raw)
            reading.error = fmt::format("asked {}, device range {}..{} step {}: set {}", value,
                                        query.minimum * unit, query.maximum * unit, step * unit,
                                        clamped * unit);
        raw = clamped;
    }
    v4l2_control control{};
    control.id = id;
    control.value = static_cast<int32_t>(raw);
    if (const int rc = xioctl(VIDIOC_S_CTRL, &control); rc < 0)
        reading.error = fmt::format("VIDIOC_S_CTRL refused {}: {}", value, errnoText(-rc));

    const ControlReading read_back = readControl(name, id, unit);
    reading.actual_value = read_back.actual_value;
    if (!read_back.error.empty())
        reading.error = read_back.error;
    else if (reading.error.empty() && read_back.actual_value != raw * unit)
        reading.error = fmt::format("device kept {}", read_back.actual_value);
    return reading;
}

std::vector<ControlReading> V4l2Device::applyControls(const CameraControls& controls,
                                                      bool lock_exposure)
{
    std::vector<ControlReading> readings;
    // Auto exposure first: the absolute exposure is inactive (or refused) while it is on.
    if (lock_exposure || controls.auto_exposure.has_value()) {
        const bool want_auto = !lock_exposure && *controls.auto_exposure;
        ControlReading reading =
            setControl("auto_exposure", V4L2_CID_EXPOSURE_AUTO,
                       want_auto ? V4L2_EXPOSURE_AUTO : V4L2_EXPOSURE_MANUAL, 1);
        // Many UVC cameras offer only manual and aperture priority (their "auto").
        if (want_auto && reading.present && !reading.error.empty()) {
            ControlReading aperture = setControl("auto_exposure", V4L2_CID_EXPOSURE_AUTO,
                                                 V4L2_EXPOSURE_APERTURE_PRIORITY, 1);
            if (aperture.error.empty())
                reading = aperture;
        }
        readings.push_back(std::move(reading));
    }
    if (controls.exposure_us.has_value()) {
        readings.push_back(
            setControl("exposure_us", V4L2_CID_EXPOSURE_ABSOLUTE, *controls.exposure_us, 100));
    } else if (lock_exposure) {
        // Freeze the exposure the device has now.
        const ControlReading current = readControl("exposure_us", V4L2_CID_EXPOSURE_ABSOLUTE, 100);
        if (current.present && current.error.empty())
            readings.push_back(
                setControl("exposure_us", V4L2_CID_EXPOSURE_ABSOLUTE, current.actual_value, 100));
        else
            readings.push_back(current);
    }
    if (controls.gain.has_value())
        readings.push_back(setControl("gain", V4L2_CID_GAIN, *controls.gain, 1));
    if (controls.auto_white_balance.has_value() || controls.white_balance_k.has_value()) {
        const bool want_auto =
            controls.white_balance_k.has_value() ? false : *controls.auto_white_balance;
        readings.push_back(
            setControl("auto_white_balance", V4L2_CID_AUTO_WHITE_BALANCE, want_auto ? 1 : 0, 1));
    }
    if (controls.white_balance_k.has_value())
        readings.push_back(setControl("white_balance_k", V4L2_CID_WHITE_BALANCE_TEMPERATURE,
                                      *controls.white_balance_k, 1));
    if (controls.power_line.has_value())
        readings.push_back(setControl("power_line_frequency", V4L2_CID_POWER_LINE_FREQUENCY,
                                      static_cast<int64_t>(*controls.power_line), 1));

    // Then everything else the project knows, as the device has it.
    for (ControlReading& reading : readControls()) {
        const bool listed =
            std::any_of(readings.begin(), readings.end(),
                        [&](const ControlReading& r) { return r.id == reading.id; });
        if (!listed)
            readings.push_back(std::move(reading));
    }
    return readings;
}

std::vector<ControlReading> V4l2Device::readControls()
{
    struct Known {
        const char* name;
        uint32_t id;
        int64_t unit;
    };
    static constexpr Known kKnown[] = {
        {"auto_exposure", V4L2_CID_EXPOSURE_AUTO, 1},
        {"exposure_us", V4L2_CID_EXPOSURE_ABSOLUTE, 100},
        {"gain", V4L2_CID_GAIN, 1},
        {"auto_white_balance", V4L2_CID_AUTO_WHITE_BALANCE, 1},
        {"white_balance_k", V4L2_CID_WHITE_BALANCE_TEMPERATURE, 1},
        {"power_line_frequency", V4L2_CID_POWER_LINE_FREQUENCY, 1},
    };
    std::vector<ControlReading> readings;
    for (const Known& known : kKnown) {
        ControlReading reading = readControl(known.name, known.id, known.unit);
        if (reading.present)
            readings.push_back(std::move(reading));
    }
    return readings;
}

} // namespace stereod
