#pragma once
// Reading the service's `raw` events for `stereoctl record` (ctl/record_command.cpp): what
// --with asks for, a raw event's payloads into a PairBuffer, and the check that the service
// sends the results asked for.
//
// Reentrant: no state; the client passed in is used by the calling thread only (the
// recorder's socket reader). Units: stamps in ns.

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "ctl/client.hpp"
#include "ctl/record_queue.hpp"

namespace stereod {

// What --with asked for.
struct Results {
    bool depth = false;
    bool points = false;
    bool any() const noexcept { return depth || points; }
};

// Parses --with. Throws UsageError naming an unknown item.
Results parseWith(const std::vector<std::string>& with);

// Reads the payloads of a raw event into `pair` (its results only when `results` asks for
// them); false (payloads read past) when the event does not carry exactly raw_left and
// raw_right.
bool readRawPair(ProtocolClient& client, const nlohmann::ordered_json& event, PairBuffer* pair,
                 const Results& results);

// The service's `with` results are missing from an event: a service older than them.
// Throws UsageError naming the socket.
void checkResultsPresent(const nlohmann::ordered_json& event, const Results& results,
                         const std::string& socket);

} // namespace stereod
