// How the configuration reads and writes scalar text: strict decimal numbers, booleans,
// file modes, and values rendered for messages. Internal to config/.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <yaml-cpp/node/node.h>

namespace stereod::config_detail {

std::string joinLines(const std::vector<std::string>& lines);
// A value as it would appear in YAML, quoted when plain text would read differently.
std::string renderText(std::string_view text);
std::string formatNumber(double value);
std::string formatMode(uint32_t mode);
// What a node is, for "got ..." in messages.
std::string describeNode(const YAML::Node& node);

// Numbers are read strictly in decimal ("09" is nine, "0x10" is not a number), unlike
// yaml-cpp's own conversions, which read a leading 0 as octal.
std::optional<double> parseReal(std::string_view text);
std::optional<int64_t> parseInteger(std::string_view text);
std::string lowercase(std::string_view text);
std::optional<bool> parseBool(std::string_view text);
std::optional<uint32_t> parseMode(std::string_view text);
// A scalar's text; empty for anything else.
std::string_view scalarText(const YAML::Node& node);

} // namespace stereod::config_detail
