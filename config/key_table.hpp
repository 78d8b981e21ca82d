// The table of every key of the configuration file, and the file's sections as a tree.
// One table drives reading, validation messages, diffConfig() and configKeys(). Internal
// to config/.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "config/key_kinds.hpp"

namespace stereod::config_detail {

// The sections and keys of the file as a tree, for reading nested mappings.
struct SchemaNode {
    std::string name;
    const KeyDef* key = nullptr;      // set for a key; a section has children instead
    std::vector<SchemaNode> children; // in file order

    const SchemaNode* child(std::string_view child_name) const
    {
        for (const auto& entry : children) {
            if (entry.name == child_name) {
                return &entry;
            }
        }
        return nullptr;
    }
};

struct Schema {
    std::vector<KeyDef> keys;
    SchemaNode root;

    const KeyDef* find(std::string_view path) const
    {
        for (const auto& def : keys) {
            if (def.path == path) {
                return &def;
            }
        }
        return nullptr;
    }
};

// Built once, on first use.
const Schema& schema();

// "a.b" from "a" and "b"; "b" alone at the top.
std::string joinPath(const std::string& prefix, std::string_view name);

// The name `matcher.algorithm` shows for these settings.
std::string algorithmName(const MatcherSettings& matcher);

const std::vector<std::string>& logLevelNames();

} // namespace stereod::config_detail
