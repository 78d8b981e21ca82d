#pragma once
// The V4L2 capture devices of this machine, for `stereoctl devices` and
// `stereod --list-devices`: what a user needs to write the cameras into the config.
//
// Reentrant: no state (it opens each device briefly, so run it while no other program
// streams from them if you want every device listed).

#include <string>
#include <vector>

#include "capture/v4l2_device.hpp"

namespace stereod {

struct DeviceInfo {
    std::string path;                     // /dev/videoN
    std::vector<std::string> by_id_paths; // /dev/v4l/by-id/... links to it (stable across
                                          // reboots and ports: use these in the config)
    DeviceIdentity identity;
    std::vector<FormatDescription> formats; // native formats, sizes and rates
};

struct DeviceList {
    std::vector<DeviceInfo> devices;   // capture devices, in device-number order
    std::vector<std::string> problems; // video nodes that could not be examined, why
};

// Every `video*` node in `dev_dir` that can capture with streaming I/O. Nodes that are
// not capture devices (metadata nodes of UVC cameras, encoders) are left out silently;
// nodes that cannot be opened (permissions, busy) are named in `problems`.
DeviceList listCaptureDevices(const std::string& dev_dir = "/dev",
                              const std::string& by_id_dir = "/dev/v4l/by-id");

// Human-readable listing: one block per device, one line per format.
std::string formatDeviceList(const DeviceList& list);

// The listing as one JSON object:
// {"devices":[{"path","by_id":[...],"driver","card","bus_info",
//   "formats":[{"fourcc","description","compressed","sizes":[{"width","height",
//   "fps":[...]} or {"min_width",...,"step_height","min_fps","max_fps"}]}]}],
//  "problems":[...]}
std::string deviceListJson(const DeviceList& list);

} // namespace stereod
