// Reading one parsed YAML document into a configuration, with every problem worded and
// placed on its line. Internal to config/.
#pragma once

#include <map>
#include <set>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "config/key_kinds.hpp"

namespace stereod::config_detail {

// Where each key of the file is, and which keys could not be read (they keep their
// defaults, and validation does not complain about them a second time).
struct KeyLocations {
    std::map<std::string, int> lines; // dotted key -> 1-based line
    std::set<std::string> unreadable;
    std::map<std::string, std::string> overridden; // dotted key -> command-line option
};

// One problem and the line it is on (0: none), so that all of them can be listed in the
// order of the file whichever check found them.
struct Problem {
    int line = 0;
    std::string key; // the key it is about; empty when about none (a syntax error)
    std::string text;
};

// The problems, in the order of their lines (those with none last).
std::vector<ConfigProblem> inLineOrder(std::vector<Problem> problems);

// Reads `root` into `config` key by key: unknown keys, keys given twice and values that
// cannot be read become problems; such keys keep their defaults.
void readDocument(const YAML::Node& root, const std::string& origin, const ReadContext& context,
                  ServiceConfig& config, KeyLocations& locations, std::vector<Problem>& problems);

} // namespace stereod::config_detail
