#include "ctl/record_events.hpp"

#include "ctl/commands.hpp"
#include "protocol/request.hpp"

namespace stereod {

using json = nlohmann::ordered_json;

Results parseWith(const std::vector<std::string>& with)
{
    Results results;
    for (const std::string& item : with) {
        if (item == "depth") {
            results.depth = true;
        } else if (item == "points") {
            results.points = true;
        } else {
            throw UsageError("--with: unknown \"" + item + "\"; accepted: depth, points");
        }
    }
    return results;
}

// The service's `with` results are missing from an event: a service older than them.
void checkResultsPresent(const json& event, const Results& results, const std::string& socket)
{
    bool depth = false;
    bool cloud = false;
    for (const json& header : event.value("payloads", json::array())) {
        const std::string name = header.value("name", std::string());
        depth = depth || name == snapshotItemName(SnapshotItem::Depth);
        cloud = cloud || name == snapshotItemName(SnapshotItem::Cloud);
    }
    if ((results.depth && !depth) || (results.points && !cloud)) {
        throw UsageError("the service at " + socket +
                         " sends no depth or points with its raw pairs (a stereod older than "
                         "`subscribe` `with`); record without --with");
    }
}

} // namespace stereod
