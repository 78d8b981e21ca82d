// The fake device description (YAML): parsing and checks.

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include <glob.h>
#include <yaml-cpp/yaml.h>

#include "tests/fake_v4l2/fake_internal.hpp"

namespace stereod::fake {
namespace {

[[noreturn]] void fail(const std::string& file, const YAML::Node& node, const std::string& what)
{
    const int line = node.Mark().line >= 0 ? node.Mark().line + 1 : 0;
    throw std::runtime_error(file + ":" + std::to_string(line) + ": " + what);
}

template <typename T>
T get(const std::string& file, const YAML::Node& map, const char* key, T fallback)
{
    const YAML::Node node = map[key];
    if (!node)
        return fallback;
    try {
        return node.as<T>();
    } catch (const YAML::Exception&) {
        fail(file, node, std::string("bad value for '") + key + "'");
    }
}

uint32_t parseFourcc(const std::string& file, const YAML::Node& node)
{
    const std::string text = node.as<std::string>();
    if (text == "GREY")
        return V4L2_PIX_FMT_GREY;
    if (text == "YUYV")
        return V4L2_PIX_FMT_YUYV;
    if (text == "MJPG")
        return V4L2_PIX_FMT_MJPEG;
    if (text == "RGB3")
        return V4L2_PIX_FMT_RGB24;
    if (text == "BGR3")
        return V4L2_PIX_FMT_BGR24;
    fail(file, node, "fourcc '" + text + "' is not GREY, YUYV, MJPG, RGB3 or BGR3");
}

// "640x480" or "640x480@30,15".
SizeSpec parseSize(const std::string& file, const YAML::Node& node,
                   const std::vector<double>& default_fps)
{
    const std::string text = node.as<std::string>();
    SizeSpec size;
    unsigned width = 0;
    unsigned height = 0;
    int consumed = 0;
    if (std::sscanf(text.c_str(), "%ux%u%n", &width, &height, &consumed) != 2 || width == 0 ||
        height == 0 || width % 2 != 0)
        fail(file, node, "size '" + text + "' is not WxH (even width)");
    size.width = width;
    size.height = height;
    std::string rest = text.substr(static_cast<size_t>(consumed));
    if (rest.empty()) {
        size.fps = default_fps;
    } else {
        if (rest[0] != '@')
            fail(file, node, "size '" + text + "': expected @fps after WxH");
        rest = rest.substr(1);
        size_t pos = 0;
        while (pos < rest.size()) {
            const size_t comma = rest.find(',', pos);
            const std::string item =
                rest.substr(pos, comma == std::string::npos ? comma : comma - pos);
            char* end = nullptr;
            const double fps = std::strtod(item.c_str(), &end);
            if (end == item.c_str() || *end != '\0' || fps <= 0.0)
                fail(file, node, "size '" + text + "': bad frame rate '" + item + "'");
            size.fps.push_back(fps);
            if (comma == std::string::npos)
                break;
            pos = comma + 1;
        }
    }
    if (size.fps.empty())
        fail(file, node, "size '" + text + "' has no frame rate (give fps: or WxH@fps)");
    return size;
}

struct KnownControl {
    const char* name;
    uint32_t id;
    ControlType type;
    int32_t minimum, maximum, step, default_value;
    std::vector<std::string> menu;
};

const std::vector<KnownControl>& knownControls()
{
    static const std::vector<KnownControl> controls = {
        {"brightness", V4L2_CID_BRIGHTNESS, ControlType::Integer, -64, 64, 1, 0, {}},
        {"contrast", V4L2_CID_CONTRAST, ControlType::Integer, 0, 64, 1, 32, {}},
        {"gain", V4L2_CID_GAIN, ControlType::Integer, 0, 255, 1, 32, {}},
        {"white_balance_automatic",
         V4L2_CID_AUTO_WHITE_BALANCE,
         ControlType::Boolean,
         0,
         1,
         1,
         1,
         {}},
        {"white_balance_temperature",
         V4L2_CID_WHITE_BALANCE_TEMPERATURE,
         ControlType::Integer,
         2800,
         6500,
         10,
         4600,
         {}},
        {"power_line_frequency",
         V4L2_CID_POWER_LINE_FREQUENCY,
         ControlType::Menu,
         0,
         2,
         1,
         1,
         {"Disabled", "50 Hz", "60 Hz"}},
        {"exposure_auto",
         V4L2_CID_EXPOSURE_AUTO,
         ControlType::Menu,
         0,
         3,
         1,
         3,
         {"Auto Mode", "Manual Mode", "Shutter Priority Mode", "Aperture Priority Mode"}},
        {"exposure_absolute",
         V4L2_CID_EXPOSURE_ABSOLUTE,
         ControlType::Integer,
         3,
         2047,
         1,
         250,
         {}},
        {"exposure_auto_priority",
         V4L2_CID_EXPOSURE_AUTO_PRIORITY,
         ControlType::Boolean,
         0,
         1,
         1,
         0,
         {}},
    };
    return controls;
}

ControlSpec parseControl(const std::string& file, const YAML::Node& node)
{
    if (!node.IsMap())
        fail(file, node, "a control is a map with name (and id, min, max, step, default)");
    ControlSpec control;
    control.name = get<std::string>(file, node, "name", "");
    const KnownControl* known = nullptr;
    for (const KnownControl& k : knownControls())
        if (control.name == k.name)
            known = &k;
    if (known != nullptr) {
        control.id = known->id;
        control.type = known->type;
        control.minimum = known->minimum;
        control.maximum = known->maximum;
        control.step = known->step;
        control.default_value = known->default_value;
        control.menu = known->menu;
    } else {
        if (!node["id"])
            fail(file, node, "control '" + control.name + "' is not a known name and has no id");
        control.id = get<uint32_t>(file, node, "id", 0);
        const std::string type = get<std::string>(file, node, "type", "integer");
        if (type == "integer")
            control.type = ControlType::Integer;
        else if (type == "boolean")
            control.type = ControlType::Boolean;
        else if (type == "menu")
            control.type = ControlType::Menu;
        else
            fail(file, node["type"], "control type '" + type + "' is not integer, boolean or menu");
        if (control.name.empty())
            control.name = "control " + std::to_string(control.id);
    }
    control.minimum = get<int32_t>(file, node, "min", control.minimum);
    control.maximum = get<int32_t>(file, node, "max", control.maximum);
    control.step = get<int32_t>(file, node, "step", control.step);
    control.default_value = get<int32_t>(file, node, "default", control.default_value);
    if (control.type == ControlType::Boolean) {
        control.minimum = 0;
        control.maximum = 1;
        control.step = 1;
    }
    if (control.type == ControlType::Menu) {
        control.step = 1;
        while (control.menu.size() < static_cast<size_t>(control.maximum) + 1)
            control.menu.push_back("Item " + std::to_string(control.menu.size()));
    }
    if (control.minimum > control.maximum || control.step <= 0 ||
        control.default_value < control.minimum || control.default_value > control.maximum)
        fail(file, node,
             "control '" + control.name + "': needs min <= default <= max and step > 0");
    return control;
}

std::vector<std::string> expandGlob(const std::string& file, const YAML::Node& node,
                                    const std::string& pattern)
{
    glob_t matches{};
    const int rc = ::glob(pattern.c_str(), 0, nullptr, &matches);
    std::vector<std::string> files;
    if (rc == 0)
        for (size_t i = 0; i < matches.gl_pathc; ++i)
            files.emplace_back(matches.gl_pathv[i]);
    globfree(&matches);
    if (files.empty())
        fail(file, node, "images '" + pattern + "' match no file");
    std::sort(files.begin(), files.end());
    return files;
}

DeviceSpec parseDevice(const std::string& file, const YAML::Node& node, size_t index)
{
    if (!node.IsMap())
        fail(file, node, "a device is a map (path, formats, images, ...)");
    DeviceSpec device;
    device.path = get<std::string>(file, node, "path", "");
    if (device.path.empty() || device.path[0] != '/')
        fail(file, node, "device needs an absolute 'path'");
    const std::string by_id = get<std::string>(file, node, "by_id", "");
    if (!by_id.empty())
        device.by_id_path = by_id[0] == '/' ? by_id : "/dev/v4l/by-id/" + by_id;
    device.driver = get<std::string>(file, node, "driver", device.driver);
    device.card = get<std::string>(file, node, "card", device.path);
    device.bus_info =
        get<std::string>(file, node, "bus_info", "usb-fake-" + std::to_string(index + 1));
    device.images_glob = get<std::string>(file, node, "images", "");
    if (device.images_glob.empty())
        fail(file, node, "device '" + device.path + "' needs 'images' (a glob)");
    device.image_files = expandGlob(file, node["images"], device.images_glob);
    device.jpeg_quality = get<int>(file, node, "jpeg_quality", 90);
    device.jitter_ms = get<double>(file, node, "jitter_ms", 0.0);
    device.phase_ms = get<double>(file, node, "phase_ms", 0.0);
    device.clock_offset_ms = get<double>(file, node, "clock_offset_ms", 0.0);
    device.clock_skew_ppm = get<double>(file, node, "clock_skew_ppm", 0.0);
    device.drop_every = get<uint32_t>(file, node, "drop_every", 0);
    const std::string stamps = get<std::string>(file, node, "timestamps", "monotonic");
    if (stamps != "monotonic" && stamps != "unknown")
        fail(file, node["timestamps"], "timestamps must be monotonic or unknown");
    device.monotonic_stamps = stamps == "monotonic";
    if (device.jitter_ms < 0.0)
        fail(file, node["jitter_ms"], "jitter_ms must be >= 0");

    std::vector<double> default_fps;
    if (const YAML::Node fps = node["fps"]) {
        if (fps.IsSequence()) {
            for (const YAML::Node& item : fps)
                default_fps.push_back(item.as<double>());
        } else {
            default_fps.push_back(fps.as<double>());
        }
        for (double value : default_fps)
            if (value <= 0.0)
                fail(file, fps, "fps must be > 0");
    }
    const YAML::Node formats = node["formats"];
    if (!formats || !formats.IsSequence() || formats.size() == 0)
        fail(file, node, "device '" + device.path + "' needs a list of 'formats'");
    for (const YAML::Node& f : formats) {
        FormatSpec format;
        if (!f["fourcc"])
            fail(file, f, "a format needs 'fourcc'");
        format.fourcc = parseFourcc(file, f["fourcc"]);
        const YAML::Node sizes = f["sizes"];
        if (!sizes || !sizes.IsSequence() || sizes.size() == 0)
            fail(file, f, "a format needs a list of 'sizes'");
        for (const YAML::Node& s : sizes)
            format.sizes.push_back(parseSize(file, s, default_fps));
        device.formats.push_back(std::move(format));
    }
    if (const YAML::Node controls = node["controls"]) {
        for (const YAML::Node& c : controls) {
            ControlSpec control = parseControl(file, c);
            for (const ControlSpec& other : device.controls)
                if (other.id == control.id)
                    fail(file, c, "control '" + control.name + "' given twice");
            device.controls.push_back(std::move(control));
        }
        std::sort(device.controls.begin(), device.controls.end(),
                  [](const ControlSpec& a, const ControlSpec& b) { return a.id < b.id; });
    }
    return device;
}

} // namespace

Description loadDescription(const std::string& path)
{
    YAML::Node root;
    try {
        root = YAML::LoadFile(path);
    } catch (const YAML::BadFile&) {
        throw std::runtime_error(path + ": cannot read the fake V4L2 description");
    } catch (const YAML::Exception& e) {
        throw std::runtime_error(path + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
    }
    Description description;
    description.source_path = path;
    try {
        if (!root.IsMap())
            fail(path, root, "the description is a map with 'devices'");
        description.control_fifo = get<std::string>(path, root, "control", "");
        description.seed = get<uint32_t>(path, root, "seed", 1);
        const YAML::Node devices = root["devices"];
        if (!devices || !devices.IsSequence() || devices.size() == 0)
            fail(path, root, "'devices' must be a non-empty list");
        for (size_t i = 0; i < devices.size(); ++i) {
            DeviceSpec device = parseDevice(path, devices[i], i);
            for (const DeviceSpec& other : description.devices)
                if (other.path == device.path ||
                    (!device.by_id_path.empty() && other.by_id_path == device.by_id_path))
                    fail(path, devices[i], "device '" + device.path + "' given twice");
            description.devices.push_back(std::move(device));
        }
    } catch (const YAML::Exception& e) {
        throw std::runtime_error(path + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
    }
    return description;
}

} // namespace stereod::fake
