// The kinds of key the configuration file has (numbers with units, booleans, names from
// a fixed set, paths, device settings that may be `keep`, ...): each makes a KeyDef that
// reads its value from YAML and shows it back. Internal to config/.
#pragma once

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "base/name_table.hpp"
#include "config/name_suggestions.hpp"
#include "config/service_config.hpp"
#include "config/yaml_scalars.hpp"
#include "model/vec3.hpp"

namespace stereod::config_detail {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------
// The keys of the file: one table drives reading, validation messages, diffConfig and
// configKeys(), so that no key can be read but not compared, or compared but not read.

inline constexpr bool kLive = true;
inline constexpr bool kRestart = false;

// Why a YAML value could not be stored: the problem and what was expected instead.
struct ReadFailure {
    std::string problem;
    std::string expected;
};
using ReadResult = std::optional<ReadFailure>;

struct ReadContext {
    // Relative paths resolve against this directory (the config file's); unset for
    // text without a file, whose relative paths stay relative to the working directory.
    std::optional<fs::path> base_dir;
};

struct KeyDef {
    std::string path; // dotted, as in the file: "nearest.roi.x"
    bool live = false;
    std::function<ReadResult(const YAML::Node&, ServiceConfig&, const ReadContext&)> read;
    // The value as YAML would write it; equal text means equal settings.
    std::function<std::string(const ServiceConfig&)> show;
};

template <class Access> KeyDef realKey(std::string path, bool live, Access access, std::string unit)
{
    KeyDef def{std::move(path), live, {}, {}};
    std::string expected = unit.empty() ? "a number" : "a number, in " + unit;
    def.read = [access, expected](const YAML::Node& node, ServiceConfig& config,
                                  const ReadContext&) -> ReadResult {
        const auto value = node.IsScalar() ? parseReal(node.Scalar()) : std::nullopt;
        if (!value) {
            return ReadFailure{"not a number", expected};
        }
        access(config) = *value;
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) { return formatNumber(access(config)); };
    return def;
}

// An integer field (int or uint32_t); its range is checked by validation, its type here.
template <class Access> KeyDef integerKey(std::string path, bool live, Access access)
{
    using Field = std::remove_cvref_t<decltype(access(std::declval<ServiceConfig&>()))>;
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access](const YAML::Node& node, ServiceConfig& config,
                        const ReadContext&) -> ReadResult {
        const auto value = node.IsScalar() ? parseInteger(node.Scalar()) : std::nullopt;
        if (!value) {
            return ReadFailure{"not an integer", "an integer"};
        }
        if (*value < static_cast<int64_t>(std::numeric_limits<Field>::min()) ||
            *value > static_cast<int64_t>(std::numeric_limits<Field>::max())) {
            return ReadFailure{"out of range",
                               "an integer from " +
                                   std::to_string(std::numeric_limits<Field>::min()) + " to " +
                                   std::to_string(std::numeric_limits<Field>::max())};
        }
        access(config) = static_cast<Field>(*value);
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) { return std::to_string(access(config)); };
    return def;
}

// "auto" (std::nullopt: the matcher decides, effectiveMatcherSettings) or an integer of at
// least `least` (the rest of its range is checked by validation); with `off`, also "off",
// stored as 0, the matcher's value for the feature turned off.
template <class Access>
KeyDef autoIntegerKey(std::string path, bool live, Access access, std::string expected,
                      int least = 1, bool off = false)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access, expected, least, off](const YAML::Node& node, ServiceConfig& config,
                                              const ReadContext&) -> ReadResult {
        if (node.IsScalar() && node.Scalar() == "auto") {
            access(config) = std::nullopt;
            return std::nullopt;
        }
        if (off && node.IsScalar() && node.Scalar() == "off") {
            access(config) = 0;
            return std::nullopt;
        }
        const auto value = node.IsScalar() ? parseInteger(node.Scalar()) : std::nullopt;
        if (!value) {
            return ReadFailure{off ? "not auto, off or an integer" : "not auto or an integer",
                               expected};
        }
        if (*value < least || *value > std::numeric_limits<int>::max()) {
            return ReadFailure{"out of range", expected};
        }
        access(config) = static_cast<int>(*value);
        return std::nullopt;
    };
    def.show = [access, off](const ServiceConfig& config) {
        const std::optional<int>& value = access(config);
        if (!value)
            return std::string("auto");
        return off && *value == 0 ? std::string("off") : std::to_string(*value);
    };
    return def;
}

// "auto" (std::nullopt) or a number, in `unit`; its range is checked by validation.
template <class Access>
KeyDef autoRealKey(std::string path, bool live, Access access, std::string unit)
{
    KeyDef def{std::move(path), live, {}, {}};
    const std::string expected = "auto or a number, in " + unit;
    def.read = [access, expected](const YAML::Node& node, ServiceConfig& config,
                                  const ReadContext&) -> ReadResult {
        if (node.IsScalar() && node.Scalar() == "auto") {
            access(config) = std::nullopt;
            return std::nullopt;
        }
        const auto value = node.IsScalar() ? parseReal(node.Scalar()) : std::nullopt;
        if (!value) {
            return ReadFailure{"not auto or a number", expected};
        }
        access(config) = *value;
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) {
        return access(config) ? formatNumber(*access(config)) : std::string("auto");
    };
    return def;
}

template <class Access> KeyDef boolKey(std::string path, bool live, Access access)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access](const YAML::Node& node, ServiceConfig& config,
                        const ReadContext&) -> ReadResult {
        const auto value = node.IsScalar() ? parseBool(node.Scalar()) : std::nullopt;
        if (!value) {
            return ReadFailure{"not true or false", "true or false"};
        }
        access(config) = *value;
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) {
        return std::string(access(config) ? "true" : "false");
    };
    return def;
}

// Three numbers, [x, y, z].
inline std::optional<Vec3> parseVec3(const YAML::Node& node)
{
    if (!node.IsSequence() || node.size() != 3)
        return std::nullopt;
    Vec3 v;
    for (std::size_t i = 0; i < 3; ++i) {
        const auto value = node[i].IsScalar() ? parseReal(node[i].Scalar()) : std::nullopt;
        if (!value)
            return std::nullopt;
        v[i] = *value;
    }
    return v;
}

inline std::string showVec3(const Vec3& v)
{
    return "[" + formatNumber(v[0]) + ", " + formatNumber(v[1]) + ", " + formatNumber(v[2]) + "]";
}

template <class Access> KeyDef vec3Key(std::string path, bool live, Access access, std::string unit)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access, unit](const YAML::Node& node, ServiceConfig& config,
                              const ReadContext&) -> ReadResult {
        const auto value = parseVec3(node);
        if (!value)
            return ReadFailure{"not a list of three numbers", "[x, y, z] in " + unit};
        access(config) = *value;
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) { return showVec3(access(config)); };
    return def;
}

// Text; an empty value (`group:`) is the empty string. Paths resolve against the
// directory of the file.
template <class Access> KeyDef textKey(std::string path, bool live, Access access, bool is_path)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access, is_path](const YAML::Node& node, ServiceConfig& config,
                                 const ReadContext& context) -> ReadResult {
        if (!node.IsNull() && !node.IsScalar()) {
            return ReadFailure{"not text", is_path ? "a path" : "text"};
        }
        std::string text = node.IsScalar() ? node.Scalar() : std::string();
        if (is_path && !text.empty() && context.base_dir && fs::path(text).is_relative()) {
            text = (*context.base_dir / text).lexically_normal().string();
        }
        access(config) = std::move(text);
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) { return renderText(access(config)); };
    return def;
}

// "auto" (std::nullopt) or a text.
template <class Access> KeyDef autoTextKey(std::string path, bool live, Access access)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access](const YAML::Node& node, ServiceConfig& config,
                        const ReadContext&) -> ReadResult {
        if (!node.IsScalar()) {
            return ReadFailure{"not text", "auto or text"};
        }
        if (node.Scalar() == "auto")
            access(config) = std::nullopt;
        else
            access(config) = node.Scalar();
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) {
        return access(config) ? renderText(*access(config)) : std::string("auto");
    };
    return def;
}

// One of a fixed set of names.
template <class Enum> using Names = std::vector<std::pair<std::string, Enum>>;

template <class Access, class Enum>
KeyDef choiceKey(std::string path, bool live, Access access, Names<Enum> names)
{
    std::vector<std::string> known;
    for (const auto& entry : names) {
        known.push_back(entry.first);
    }
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access, names, known](const YAML::Node& node, ServiceConfig& config,
                                      const ReadContext&) -> ReadResult {
        if (node.IsScalar()) {
            for (const auto& [name, value] : names) {
                if (node.Scalar() == name) {
                    access(config) = value;
                    return std::nullopt;
                }
            }
        }
        return ReadFailure{"unknown value", expectedOneOf(known, scalarText(node))};
    };
    def.show = [access, names](const ServiceConfig& config) {
        for (const auto& [name, value] : names) {
            if (access(config) == value) {
                return name;
            }
        }
        return std::string("?");
    };
    return def;
}

// One of the names of the enum's table (base/name_table.hpp), the one list of them.
template <class Access, class Enum, std::size_t N>
KeyDef choiceKey(std::string path, bool live, Access access, const NameTable<Enum, N>& table)
{
    Names<Enum> names;
    for (const auto& entry : table.entries) {
        names.emplace_back(entry.name, entry.value);
    }
    return choiceKey(std::move(path), live, access, std::move(names));
}

// An optional device setting: `keep` (unset: the device keeps its own value) or a value
// that `parse` reads (nothing when the text is not one); `show` renders a set value.
inline constexpr std::string_view kKeep = "keep";

template <class Access, class Parse, class Show>
KeyDef keepKey(std::string path, bool live, Access access, std::string problem,
               std::string expected, Parse parse, Show show)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access, problem, expected, parse](const YAML::Node& node, ServiceConfig& config,
                                                  const ReadContext&) -> ReadResult {
        if (node.IsScalar() && node.Scalar() == kKeep) {
            access(config).reset();
            return std::nullopt;
        }
        auto value = node.IsScalar() ? parse(node.Scalar()) : std::nullopt;
        if (!value) {
            return ReadFailure{problem, expected};
        }
        access(config) = *value;
        return std::nullopt;
    };
    def.show = [access, show](const ServiceConfig& config) {
        return access(config) ? show(*access(config)) : std::string(kKeep);
    };
    return def;
}

template <class Access> KeyDef keepIntegerKey(std::string path, Access access, std::string unit)
{
    return keepKey(
        std::move(path), kRestart, access, "not keep or an integer",
        "keep, or an integer" + (unit.empty() ? std::string() : " in " + unit),
        [](std::string_view text) -> std::optional<int32_t> {
            const auto value = parseInteger(text);
            if (!value || *value < std::numeric_limits<int32_t>::min() ||
                *value > std::numeric_limits<int32_t>::max()) {
                return std::nullopt;
            }
            return static_cast<int32_t>(*value);
        },
        [](int32_t value) { return std::to_string(value); });
}

template <class Access> KeyDef keepBoolKey(std::string path, Access access)
{
    return keepKey(
        std::move(path), kRestart, access, "not keep, true or false", "keep, true or false",
        [](std::string_view text) { return parseBool(text); },
        [](bool value) { return std::string(value ? "true" : "false"); });
}

// A list of user or group ids: `[1000, 1001]`, or empty (`[]` or nothing). The id
// 4294967295 is (uid_t)-1, "no id", so it is refused.
template <class Access> KeyDef idListKey(std::string path, bool live, Access access)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access](const YAML::Node& node, ServiceConfig& config,
                        const ReadContext&) -> ReadResult {
        const std::string expected =
            "a list of numeric ids from 0 to 4294967294, like [1000, 1001]";
        std::vector<uint32_t> ids;
        if (!node.IsNull() && !node.IsSequence()) {
            return ReadFailure{"not a list", expected};
        }
        for (const auto& item : node) {
            const auto value = item.IsScalar() ? parseInteger(item.Scalar()) : std::nullopt;
            if (!value || *value < 0 || *value >= int64_t{std::numeric_limits<uint32_t>::max()}) {
                return ReadFailure{"not a list of ids", expected};
            }
            ids.push_back(static_cast<uint32_t>(*value));
        }
        access(config) = std::move(ids);
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) {
        std::string text = "[";
        for (const uint32_t id : access(config)) {
            text += (text.size() > 1 ? ", " : "") + std::to_string(id);
        }
        return text + "]";
    };
    return def;
}

// A list of texts: `["https://app.foxglove.dev"]`, or empty (`[]` or nothing).
template <class Access> KeyDef textListKey(std::string path, bool live, Access access)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access](const YAML::Node& node, ServiceConfig& config,
                        const ReadContext&) -> ReadResult {
        const std::string expected = "a list of texts, like [\"https://app.foxglove.dev\"]";
        std::vector<std::string> texts;
        if (!node.IsNull() && !node.IsSequence()) {
            return ReadFailure{"not a list", expected};
        }
        for (const auto& item : node) {
            if (!item.IsScalar()) {
                return ReadFailure{"not a list of texts", expected};
            }
            texts.push_back(item.Scalar());
        }
        access(config) = std::move(texts);
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) {
        std::string text = "[";
        for (const std::string& item : access(config)) {
            text += (text.size() > 1 ? ", " : "") + renderText(item);
        }
        return text + "]";
    };
    return def;
}

} // namespace stereod::config_detail
