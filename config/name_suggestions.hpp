// "Did you mean": the closest known name, for messages about unknown keys and values.
// Internal to config/.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace stereod::config_detail {

// Lowercase, with '-' and '_' alike, so that "Min-Pixels" finds "min_pixels".
std::string normalizedName(std::string_view name);
std::optional<std::string> closestName(std::string_view given,
                                       const std::vector<std::string>& known);
std::string listNames(const std::vector<std::string>& names);
// "one of a, b or c", with a suggestion when `given` is close to one of them.
std::string expectedOneOf(const std::vector<std::string>& known, std::string_view given);

} // namespace stereod::config_detail
