#include "capture/device_list.hpp"

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>

#include <dirent.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <string.h>

namespace stereod {

namespace {

std::vector<std::string> directoryEntries(const std::string& dir)
{
    std::vector<std::string> names;
    DIR* handle = ::opendir(dir.c_str());
    if (handle == nullptr)
        return names;
    while (const dirent* entry = ::readdir(handle)) {
        const std::string name = entry->d_name;
        if (name != "." && name != "..")
            names.push_back(name);
    }
    ::closedir(handle);
    return names;
}

std::string resolved(const std::string& path)
{
    char buffer[PATH_MAX];
    return ::realpath(path.c_str(), buffer) != nullptr ? std::string(buffer) : path;
}

} // namespace

DeviceList listCaptureDevices(const std::string& dev_dir, const std::string& by_id_dir)
{
    std::vector<std::string> nodes;
    for (const std::string& name : directoryEntries(dev_dir)) {
        if (name.rfind("video", 0) == 0)
            nodes.push_back(name);
    }
    // video2 before video10.
    std::sort(nodes.begin(), nodes.end(), [](const std::string& a, const std::string& b) {
        return strverscmp(a.c_str(), b.c_str()) < 0;
    });

    std::vector<std::pair<std::string, std::string>> by_id; // (link, its target)
    for (const std::string& name : directoryEntries(by_id_dir)) {
        const std::string link = by_id_dir + "/" + name;
        by_id.emplace_back(link, resolved(link));
    }
    std::sort(by_id.begin(), by_id.end());

    DeviceList list;
    for (const std::string& name : nodes) {
        const std::string path = dev_dir + "/" + name;
        V4l2Device device;
        const int rc = device.open(path);
        if (rc == -ENODEV || rc == -ENOTTY)
            continue; // not a capture device: a UVC metadata node, an encoder, ...
        if (rc < 0) {
            list.problems.push_back(device.errorText());
            continue;
        }
        DeviceInfo info;
        info.path = path;
        info.identity = device.identity();
        if (device.enumerateFormats(info.formats) < 0)
            list.problems.push_back(device.errorText());
        const std::string target = resolved(path);
        for (const auto& [link, link_target] : by_id) {
            if (link_target == target)
                info.by_id_paths.push_back(link);
        }
        list.devices.push_back(std::move(info));
    }
    return list;
}

std::string formatDeviceList(const DeviceList& list)
{
    std::string text;
    for (const DeviceInfo& device : list.devices) {
        text += fmt::format("{}: {} (driver {}, bus {})\n", device.path, device.identity.card,
                            device.identity.driver, device.identity.bus_info);
        for (const std::string& link : device.by_id_paths)
            text += fmt::format("  by-id: {}\n", link);
        if (device.by_id_paths.empty())
            text += "  by-id: none (the path may change between boots)\n";
        for (const FormatDescription& format : device.formats)
            text += fmt::format("  {} ({})\n", describeFormat(format), format.description);
        if (device.formats.empty())
            text += "  no formats listed\n";
    }
    if (list.devices.empty())
        text += "no V4L2 capture devices found\n";
    for (const std::string& problem : list.problems)
        text += fmt::format("could not examine {}\n", problem);
    return text;
}

std::string deviceListJson(const DeviceList& list)
{
    nlohmann::ordered_json devices = nlohmann::ordered_json::array();
    for (const DeviceInfo& device : list.devices) {
        nlohmann::ordered_json formats = nlohmann::ordered_json::array();
        for (const FormatDescription& format : device.formats) {
            nlohmann::ordered_json sizes = nlohmann::ordered_json::array();
            for (const FrameSizeDescription& size : format.sizes) {
                nlohmann::ordered_json entry;
                if (size.isRange()) {
                    entry["min_width"] = size.width;
                    entry["min_height"] = size.height;
                    entry["max_width"] = size.max_width;
                    entry["max_height"] = size.max_height;
                    entry["step_width"] = size.step_width;
                    entry["step_height"] = size.step_height;
                } else {
                    entry["width"] = size.width;
                    entry["height"] = size.height;
                }
                if (size.max_fps > 0.0) {
                    entry["min_fps"] = size.min_fps;
                    entry["max_fps"] = size.max_fps;
                } else {
                    entry["fps"] = size.fps;
                }
                sizes.push_back(std::move(entry));
            }
            formats.push_back({{"fourcc", format.name},
                               {"description", format.description},
                               {"compressed", format.compressed},
                               {"sizes", std::move(sizes)}});
        }
        devices.push_back({{"path", device.path},
                           {"by_id", device.by_id_paths},
                           {"driver", device.identity.driver},
                           {"card", device.identity.card},
                           {"bus_info", device.identity.bus_info},
                           {"formats", std::move(formats)}});
    }
    nlohmann::ordered_json out;
    out["devices"] = std::move(devices);
    out["problems"] = list.problems;
    return out.dump(2);
}

} // namespace stereod
