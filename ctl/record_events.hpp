#pragma once
// Reading the service's `raw` events for `stereoctl record` (ctl/record_command.cpp): what
// --with asks for, and the check that the service sends the results asked for (the pair
// itself is read by ctl/raw_pair.hpp).
//
// Reentrant: no state; the client passed in is used by the calling thread only (the
// recorder's socket reader). Units: stamps in ns.

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "ctl/raw_pair.hpp"

namespace stereod {

// Parses --with. Throws UsageError naming an unknown item.
Results parseWith(const std::vector<std::string>& with);

// The service's `with` results are missing from an event: a service older than them.
// Throws UsageError naming the socket.
void checkResultsPresent(const nlohmann::ordered_json& event, const Results& results,
                         const std::string& socket);

} // namespace stereod
