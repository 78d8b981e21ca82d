// Checking the values of a configuration (ranges, paths, cameras, the matcher's own
// limits, the socket's owner), each problem worded with its key and line. Internal to
// config/.
#pragma once

#include <vector>

#include "config/document_reader.hpp"

namespace stereod::config_detail {

// Every problem of `config`'s values; keys that `locations` marks unreadable are not
// reported again.
std::vector<Problem> checkValues(const ServiceConfig& config, const KeyLocations& locations);

} // namespace stereod::config_detail
