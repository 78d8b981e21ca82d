// `stereoctl devices`: the V4L2 capture devices of this machine with their formats, sizes,
// rates and stable /dev/v4l/by-id paths, to write the cameras into the config.

#include <cstdio>

#include <fmt/format.h>

#include "capture/device_list.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"

namespace stereod {

int runDevices(const DevicesOptions& options)
{
    const DeviceList list = listCaptureDevices();
    if (options.json)
        fmt::print("{}\n", deviceListJson(list));
    else
        std::fputs(formatDeviceList(list).c_str(), stdout);
    return list.devices.empty() ? kExitNoReading : kExitOk;
}

} // namespace stereod
