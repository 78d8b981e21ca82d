#include "config/service_config.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <utility>

#include <grp.h>
#include <sys/un.h>
#include <unistd.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include "pipeline/census_sgm_matcher.hpp"

namespace stereod {

namespace fs = std::filesystem;

namespace {

// ---------------------------------------------------------------------------------------
// Rendering values in messages

std::string joinLines(const std::vector<std::string>& lines)
{
    std::string out;
    for (const auto& line : lines) {
        if (!out.empty()) {
            out += '\n';
        }
        out += line;
    }
    return out;
}

// A value as a message shows it: bare when it is one plain token, quoted otherwise, with
// control characters escaped and very long values shortened (longer than any path), so
// that one problem stays on one line whatever the file holds.
std::string renderText(std::string_view text)
{
    constexpr size_t kMaxShown = 4096;
    constexpr std::string_view kPlainPunctuation = "._+-/";
    const bool plain = !text.empty() && std::all_of(text.begin(), text.end(), [&](char ch) {
        return std::isalnum(static_cast<unsigned char>(ch)) ||
               kPlainPunctuation.find(ch) != std::string_view::npos;
    });
    std::string out;
    if (!plain) {
        out += '"';
    }
    for (size_t i = 0; i < std::min(text.size(), kMaxShown); ++i) {
        const auto ch = static_cast<unsigned char>(text[i]);
        if (ch == '"' || ch == '\\') {
            out += '\\';
            out += static_cast<char>(ch);
        } else if (ch == '\n') {
            out += "\\n";
        } else if (ch == '\t') {
            out += "\\t";
        } else if (ch < 0x20 || ch == 0x7f) {
            char escaped[8];
            std::snprintf(escaped, sizeof escaped, "\\x%02x", ch);
            out += escaped;
        } else {
            out += static_cast<char>(ch);
        }
    }
    if (text.size() > kMaxShown) {
        out += "...";
    }
    if (!plain) {
        out += '"';
    }
    return out;
}

// Shortest text that reads back as the same double (0.1 -> "0.1", 600000 -> "600000"),
// in plain decimals unless the number is very large or very small.
std::string formatNumber(double value)
{
    char buffer[512];
    const double magnitude = std::fabs(value);
    const bool plain = magnitude == 0.0 || (magnitude >= 1e-4 && magnitude < 1e15);
    const auto result =
        plain ? std::to_chars(buffer, buffer + sizeof buffer, value, std::chars_format::fixed)
              : std::to_chars(buffer, buffer + sizeof buffer, value);
    return std::string(buffer, result.ptr);
}

std::string formatMode(uint32_t mode)
{
    char buffer[16];
    std::snprintf(buffer, sizeof buffer, "%04o", static_cast<unsigned>(mode));
    return buffer;
}

// How a YAML value is shown after "got": the text of a scalar, or what kind of node it is.
std::string describeNode(const YAML::Node& node)
{
    switch (node.Type()) {
    case YAML::NodeType::Scalar:
        return renderText(node.Scalar());
    case YAML::NodeType::Sequence:
        return "a list";
    case YAML::NodeType::Map:
        return "a mapping";
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined:
        break;
    }
    return "nothing";
}

// ---------------------------------------------------------------------------------------
// Scalars. Numbers are read strictly in decimal ("09" is nine, "0x10" is not a number),
// unlike yaml-cpp's own conversions, which read a leading 0 as octal.

std::string_view withoutPlus(std::string_view text)
{
    if (text.size() > 1 && text.front() == '+' && text[1] != '-') {
        text.remove_prefix(1);
    }
    return text;
}

std::optional<double> parseReal(std::string_view text)
{
    text = withoutPlus(text);
    double value = 0.0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || ec != std::errc() || end != text.data() + text.size()) {
        return std::nullopt;
    }
    return value;
}

std::optional<int64_t> parseInteger(std::string_view text)
{
    text = withoutPlus(text);
    int64_t value = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (text.empty() || ec != std::errc() || end != text.data() + text.size()) {
        return std::nullopt;
    }
    return value;
}

std::string lowercase(std::string_view text)
{
    std::string out(text);
    std::transform(out.begin(), out.end(), out.begin(),
                   [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
    return out;
}

// YAML's words for true and false, in any case.
std::optional<bool> parseBool(std::string_view text)
{
    const std::string word = lowercase(text);
    if (word == "true" || word == "yes" || word == "on") {
        return true;
    }
    if (word == "false" || word == "no" || word == "off") {
        return false;
    }
    return std::nullopt;
}

// A file mode in octal, as chmod takes it: "0660", 0660, 660 and 0o660 are all rw-rw----.
std::optional<uint32_t> parseMode(std::string_view text)
{
    if (text.size() > 2 && text[0] == '0' && (text[1] == 'o' || text[1] == 'O')) {
        text.remove_prefix(2);
    }
    uint32_t value = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value, 8);
    if (text.empty() || ec != std::errc() || end != text.data() + text.size()) {
        return std::nullopt;
    }
    return value;
}

// ---------------------------------------------------------------------------------------
// "Did you mean": the closest known name, by edit distance with transpositions.

std::string normalizedName(std::string_view name)
{
    std::string out = lowercase(name);
    std::replace(out.begin(), out.end(), '-', '_');
    std::replace(out.begin(), out.end(), ' ', '_');
    return out;
}

size_t editDistance(std::string_view a, std::string_view b)
{
    std::vector<std::vector<size_t>> d(a.size() + 1, std::vector<size_t>(b.size() + 1));
    for (size_t i = 0; i <= a.size(); ++i) {
        d[i][0] = i;
    }
    for (size_t j = 0; j <= b.size(); ++j) {
        d[0][j] = j;
    }
    for (size_t i = 1; i <= a.size(); ++i) {
        for (size_t j = 1; j <= b.size(); ++j) {
            const size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
            d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) {
                d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
            }
        }
    }
    return d[a.size()][b.size()];
}

std::optional<std::string> closestName(std::string_view given,
                                       const std::vector<std::string>& candidates)
{
    // Long names tolerate more typos; a short one must be nearly right to be suggested.
    const std::string wanted = normalizedName(given);
    if (wanted.size() > 64) {
        return std::nullopt;
    }
    const size_t tolerance = wanted.size() <= 3 ? 1 : wanted.size() <= 8 ? 2 : 3;
    std::optional<std::string> best;
    size_t best_distance = tolerance + 1;
    for (const auto& candidate : candidates) {
        const size_t distance = editDistance(wanted, normalizedName(candidate));
        if (distance < best_distance) {
            best_distance = distance;
            best = candidate;
        }
    }
    return best;
}

std::string listNames(const std::vector<std::string>& names)
{
    std::string out;
    for (size_t i = 0; i < names.size(); ++i) {
        out += i == 0 ? "" : i + 1 == names.size() ? " or " : ", ";
        out += names[i];
    }
    return out;
}

// What a message expects of a name: "a, b or c", and the closest to what was given.
std::string expectedOneOf(const std::vector<std::string>& known, std::string_view given)
{
    std::string expected = listNames(known);
    if (auto suggestion = closestName(given, known)) {
        expected += "; did you mean " + *suggestion + "?";
    }
    return expected;
}

std::string_view scalarText(const YAML::Node& node)
{
    return node.IsScalar() ? std::string_view(node.Scalar()) : std::string_view();
}

// ---------------------------------------------------------------------------------------
// The keys of the file: one table drives reading, validation messages, diffConfig and
// configKeys(), so that no key can be read but not compared, or compared but not read.

constexpr bool kLive = true;
constexpr bool kRestart = false;

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

// "auto" (stored as 0) or a positive integer.
template <class Access>
KeyDef autoIntegerKey(std::string path, bool live, Access access, std::string expected)
{
    KeyDef def{std::move(path), live, {}, {}};
    def.read = [access, expected](const YAML::Node& node, ServiceConfig& config,
                                  const ReadContext&) -> ReadResult {
        if (node.IsScalar() && node.Scalar() == "auto") {
            access(config) = 0;
            return std::nullopt;
        }
        const auto value = node.IsScalar() ? parseInteger(node.Scalar()) : std::nullopt;
        if (!value) {
            return ReadFailure{"not auto or an integer", expected};
        }
        if (*value < 1 || *value > std::numeric_limits<int>::max()) {
            return ReadFailure{"out of range", expected};
        }
        access(config) = static_cast<int>(*value);
        return std::nullopt;
    };
    def.show = [access](const ServiceConfig& config) {
        return access(config) == 0 ? std::string("auto") : std::to_string(access(config));
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
std::optional<cv::Vec3d> parseVec3(const YAML::Node& node)
{
    if (!node.IsSequence() || node.size() != 3)
        return std::nullopt;
    cv::Vec3d v;
    for (std::size_t i = 0; i < 3; ++i) {
        const auto value = node[i].IsScalar() ? parseReal(node[i].Scalar()) : std::nullopt;
        if (!value)
            return std::nullopt;
        v[static_cast<int>(i)] = *value;
    }
    return v;
}

std::string showVec3(const cv::Vec3d& v)
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

// The keep-out zones: a list of boxes in the robot's base frame.
KeyDef zonesKey()
{
    KeyDef def{"zones", kLive, {}, {}};
    def.read = [](const YAML::Node& node, ServiceConfig& config, const ReadContext&) -> ReadResult {
        const std::string expected =
            "a list of {name, min: [x, y, z], max: [x, y, z], min_points, enter_frames, "
            "leave_frames}, metres in the robot's base frame";
        if (!node.IsNull() && !node.IsSequence())
            return ReadFailure{"not a list", expected};
        std::vector<ZoneSettings> zones;
        for (std::size_t i = 0; i < node.size(); ++i) {
            const YAML::Node item = node[i];
            const std::string where = "zone " + std::to_string(i + 1);
            if (!item.IsMap())
                return ReadFailure{where + " is not a mapping", expected};
            ZoneSettings zone;
            for (const auto& entry : item) {
                const std::string key = entry.first.as<std::string>();
                const YAML::Node& value = entry.second;
                if (key == "name" && value.IsScalar()) {
                    zone.name = value.Scalar();
                } else if (key == "min" || key == "max") {
                    const auto v = parseVec3(value);
                    if (!v)
                        return ReadFailure{where + ": " + key + " is not [x, y, z]", expected};
                    (key == "min" ? zone.min_m : zone.max_m) = *v;
                } else if (key == "min_points" || key == "enter_frames" || key == "leave_frames") {
                    const auto v = value.IsScalar() ? parseInteger(value.Scalar()) : std::nullopt;
                    if (!v || *v < 1 || *v > 1000000)
                        return ReadFailure{where + ": " + key + " is not a whole number >= 1",
                                           expected};
                    (key == "min_points"     ? zone.min_points
                     : key == "enter_frames" ? zone.enter_frames
                                             : zone.leave_frames) = static_cast<int>(*v);
                } else {
                    return ReadFailure{where + ": unknown key " + key, expected};
                }
            }
            zones.push_back(std::move(zone));
        }
        config.zones.zones = std::move(zones);
        return std::nullopt;
    };
    def.show = [](const ServiceConfig& config) {
        std::string text = "[";
        for (const ZoneSettings& z : config.zones.zones)
            text += (text.size() > 1 ? ", " : "") + std::string("{name: ") + z.name +
                    ", min: " + showVec3(z.min_m) + ", max: " + showVec3(z.max_m) +
                    ", min_points: " + std::to_string(z.min_points) +
                    ", enter_frames: " + std::to_string(z.enter_frames) +
                    ", leave_frames: " + std::to_string(z.leave_frames) + "}";
        return text + "]";
    };
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

// An optional device setting: `keep` (unset: the device keeps its own value) or a value
// that `parse` reads (nothing when the text is not one); `show` renders a set value.
constexpr std::string_view kKeep = "keep";

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

const Names<PowerLineFrequency>& powerLineNames()
{
    static const Names<PowerLineFrequency> names = {{"disabled", PowerLineFrequency::Disabled},
                                                    {"50hz", PowerLineFrequency::Hz50},
                                                    {"60hz", PowerLineFrequency::Hz60},
                                                    {"auto", PowerLineFrequency::Auto}};
    return names;
}

KeyDef powerLineKey()
{
    std::vector<std::string> known{std::string(kKeep)};
    for (const auto& entry : powerLineNames()) {
        known.push_back(entry.first);
    }
    return keepKey(
        "source.cameras.controls.power_line_frequency", kRestart,
        [](auto& c) -> auto& { return c.source.cameras.controls.power_line; }, "unknown value",
        listNames(known),
        [](std::string_view text) -> std::optional<PowerLineFrequency> {
            for (const auto& [name, value] : powerLineNames()) {
                if (text == name) {
                    return value;
                }
            }
            return std::nullopt;
        },
        [](PowerLineFrequency value) {
            for (const auto& [name, entry] : powerLineNames()) {
                if (entry == value) {
                    return name;
                }
            }
            return std::string("?");
        });
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

// The matcher's name sets two fields: the OpenCV matcher and, for SGBM, its mode.
struct AlgorithmName {
    std::string name;
    MatcherKind kind;
    SgbmMode mode;
};

const std::vector<AlgorithmName>& algorithmNames()
{
    static const std::vector<AlgorithmName> names = {
        {"census-sgm", MatcherKind::CensusSgm, SgbmMode::Sgbm},
        {"sgbm", MatcherKind::Sgbm, SgbmMode::Sgbm},
        {"sgbm-3way", MatcherKind::Sgbm, SgbmMode::ThreeWay},
        {"sgbm-hh", MatcherKind::Sgbm, SgbmMode::Hh},
        {"sgbm-hh4", MatcherKind::Sgbm, SgbmMode::Hh4},
        {"bm", MatcherKind::Bm, SgbmMode::Sgbm},
    };
    return names;
}

std::string algorithmName(const MatcherSettings& matcher)
{
    for (const auto& entry : algorithmNames()) {
        if (entry.kind == matcher.kind &&
            (matcher.kind != MatcherKind::Sgbm || entry.mode == matcher.sgbm_mode)) {
            return entry.name;
        }
    }
    return "?";
}

KeyDef algorithmKey()
{
    KeyDef def{"matcher.algorithm", kLive, {}, {}};
    def.read = [](const YAML::Node& node, ServiceConfig& config, const ReadContext&) -> ReadResult {
        std::vector<std::string> known;
        for (const auto& entry : algorithmNames()) {
            if (node.IsScalar() && node.Scalar() == entry.name) {
                config.processing.matcher.kind = entry.kind;
                config.processing.matcher.sgbm_mode = entry.mode;
                return std::nullopt;
            }
            known.push_back(entry.name);
        }
        return ReadFailure{"unknown matcher", expectedOneOf(known, scalarText(node))};
    };
    def.show = [](const ServiceConfig& config) { return algorithmName(config.processing.matcher); };
    return def;
}

KeyDef modeKey()
{
    KeyDef def{"socket.mode", kRestart, {}, {}};
    def.read = [](const YAML::Node& node, ServiceConfig& config, const ReadContext&) -> ReadResult {
        const auto mode = node.IsScalar() ? parseMode(node.Scalar()) : std::nullopt;
        if (!mode) {
            return ReadFailure{"not an octal file mode", "octal digits, like \"0660\""};
        }
        config.socket.mode = *mode;
        return std::nullopt;
    };
    def.show = [](const ServiceConfig& config) {
        return "\"" + formatMode(config.socket.mode) + "\"";
    };
    return def;
}

const std::vector<std::string>& logLevelNames()
{
    // spdlog's level names (spdlog::level::to_string_view), least severe first.
    static const std::vector<std::string> names = {"trace", "debug",    "info", "warn",
                                                   "error", "critical", "off"};
    return names;
}

std::vector<KeyDef> buildKeyTable()
{
    std::vector<KeyDef> keys;
    const auto add = [&keys](KeyDef def) { keys.push_back(std::move(def)); };

    add(choiceKey(
        "source.type", kRestart, [](auto& c) -> auto& { return c.source.kind; },
        Names<SourceKind>{{"replay", SourceKind::Replay},
                          {"v4l2", SourceKind::V4l2},
                          {"side_by_side", SourceKind::SideBySide}}));
    add(textKey(
        "source.replay.path", kRestart, [](auto& c) -> auto& { return c.source.replay.path; },
        true));
    add(choiceKey(
        "source.replay.pacing", kRestart, [](auto& c) -> auto& { return c.source.replay.pacing; },
        Names<ReplayPacing>{{"paced", ReplayPacing::Paced}, {"lockstep", ReplayPacing::Lockstep}}));
    add(realKey(
        "source.replay.fps", kRestart, [](auto& c) -> auto& { return c.source.replay.fps; },
        "frames per second"));
    add(boolKey(
        "source.replay.loop", kRestart, [](auto& c) -> auto& { return c.source.replay.loop; }));
    add(textKey(
        "source.replay.topics.left", kRestart,
        [](auto& c) -> auto& { return c.source.replay.left_topic; }, false));
    add(textKey(
        "source.replay.topics.right", kRestart,
        [](auto& c) -> auto& { return c.source.replay.right_topic; }, false));
    add(textKey(
        "source.cameras.left", kRestart, [](auto& c) -> auto& { return c.source.cameras.left; },
        false));
    add(textKey(
        "source.cameras.right", kRestart, [](auto& c) -> auto& { return c.source.cameras.right; },
        false));
    add(textKey(
        "source.cameras.device", kRestart, [](auto& c) -> auto& { return c.source.cameras.device; },
        false));
    add(choiceKey(
        "source.cameras.format", kRestart, [](auto& c) -> auto& { return c.source.cameras.format; },
        Names<PixelFormatChoice>{{"auto", PixelFormatChoice::Auto},
                                 {"grey", PixelFormatChoice::Grey},
                                 {"yuyv", PixelFormatChoice::Yuyv},
                                 {"mjpeg", PixelFormatChoice::Mjpeg}}));
    add(integerKey(
        "source.cameras.width", kRestart, [](auto& c) -> auto& { return c.source.cameras.width; }));
    add(integerKey(
        "source.cameras.height", kRestart,
        [](auto& c) -> auto& { return c.source.cameras.height; }));
    add(realKey(
        "source.cameras.fps", kRestart, [](auto& c) -> auto& { return c.source.cameras.fps; },
        "frames per second"));
    add(boolKey(
        "source.cameras.lock_exposure", kRestart,
        [](auto& c) -> auto& { return c.source.cameras.lock_exposure; }));
    add(keepBoolKey(
        "source.cameras.controls.auto_exposure",
        [](auto& c) -> auto& { return c.source.cameras.controls.auto_exposure; }));
    add(keepIntegerKey(
        "source.cameras.controls.exposure_us",
        [](auto& c) -> auto& { return c.source.cameras.controls.exposure_us; }, "us"));
    add(keepIntegerKey(
        "source.cameras.controls.gain",
        [](auto& c) -> auto& { return c.source.cameras.controls.gain; }, "device units"));
    add(keepBoolKey(
        "source.cameras.controls.auto_white_balance",
        [](auto& c) -> auto& { return c.source.cameras.controls.auto_white_balance; }));
    add(keepIntegerKey(
        "source.cameras.controls.white_balance_k",
        [](auto& c) -> auto& { return c.source.cameras.controls.white_balance_k; }, "kelvin"));
    add(powerLineKey());
    add(integerKey(
        "source.ring_capacity", kRestart, [](auto& c) -> auto& { return c.source.ring_capacity; }));
    add(realKey(
        "source.max_skew_ms", kRestart, [](auto& c) -> auto& { return c.source.max_skew_ms; },
        "ms"));
    add(realKey(
        "source.stall_timeout_ms", kRestart,
        [](auto& c) -> auto& { return c.source.stall_timeout_ms; }, "ms"));
    add(textKey(
        "calibration", kRestart, [](auto& c) -> auto& { return c.calibration_path; }, true));

    add(algorithmKey());
    add(realKey(
        "matcher.min_depth_m", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.min_depth_m; }, "m"));
    add(autoIntegerKey(
        "matcher.num_disparities", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.num_disparities; },
        "auto or a positive multiple of 16"));
    add(integerKey(
        "matcher.max_num_disparities", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.max_num_disparities; }));
    add(integerKey(
        "matcher.min_disparity", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.min_disparity; }));
    add(integerKey(
        "matcher.block_size", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.block_size; }));
    add(integerKey(
        "matcher.uniqueness_ratio", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.uniqueness_ratio; }));
    add(integerKey(
        "matcher.speckle_window_px", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.speckle_window_px; }));
    add(integerKey(
        "matcher.speckle_range_px", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.speckle_range_px; }));
    add(integerKey(
        "matcher.lr_max_diff_px", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.lr_max_diff_px; }));
    add(autoIntegerKey(
        "matcher.p1", kLive, [](auto& c) -> auto& { return c.processing.matcher.p1; },
        "auto or an integer from 1 to 32767"));
    add(autoIntegerKey(
        "matcher.p2", kLive, [](auto& c) -> auto& { return c.processing.matcher.p2; },
        "auto or an integer from 1 to 32767"));
    add(integerKey(
        "matcher.pre_filter_cap", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.pre_filter_cap; }));
    add(integerKey(
        "matcher.texture_threshold", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.texture_threshold; }));
    add(autoIntegerKey(
        "matcher.census_width", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.census_width; },
        "auto or an odd number of pixels"));
    add(autoIntegerKey(
        "matcher.census_height", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.census_height; },
        "auto or an odd number of pixels"));
    add(autoIntegerKey(
        "matcher.paths", kLive, [](auto& c) -> auto& { return c.processing.matcher.paths; },
        "auto, 3 or 5"));
    add(autoIntegerKey(
        "matcher.p2_gradient_scale", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.p2_gradient_scale; },
        "auto or grey levels"));
    add(autoIntegerKey(
        "matcher.threads", kLive, [](auto& c) -> auto& { return c.processing.matcher.threads; },
        "auto (the cores available) or a number of threads"));

    add(realKey(
        "nearest.roi.x", kLive, [](auto& c) -> auto& { return c.processing.nearest.roi.x; },
        "image widths"));
    add(realKey(
        "nearest.roi.y", kLive, [](auto& c) -> auto& { return c.processing.nearest.roi.y; },
        "image heights"));
    add(realKey(
        "nearest.roi.width", kLive, [](auto& c) -> auto& { return c.processing.nearest.roi.width; },
        "image widths"));
    add(realKey(
        "nearest.roi.height", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.roi.height; }, "image heights"));
    add(realKey(
        "nearest.min_depth_m", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_depth_m; }, "m"));
    add(realKey(
        "nearest.max_depth_m", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.max_depth_m; }, "m"));
    add(realKey(
        "nearest.percentile", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.percentile; }, "percent"));
    add(realKey(
        "nearest.min_valid_fraction", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_valid_fraction; }, ""));
    add(integerKey(
        "nearest.min_pixels", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_pixels; }));
    add(realKey(
        "nearest.min_in_range_fraction", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_in_range_fraction; }, ""));
    add(integerKey(
        "nearest.min_confidence", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_confidence; }));
    add(realKey(
        "nearest.range_limit_fraction", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.range_limit_fraction; }, ""));
    add(boolKey(
        "point_cloud", kLive, [](auto& c) -> auto& { return c.processing.compute_cloud; }));
    add(vec3Key(
        "robot.camera_pose.translation_m", kLive,
        [](auto& c) -> auto& { return c.zones.camera_pose.translation_m; }, "metres"));
    add(vec3Key(
        "robot.camera_pose.rpy_deg", kLive,
        [](auto& c) -> auto& { return c.zones.camera_pose.rpy_deg; }, "degrees"));
    add(realKey(
        "robot.min_visible_fraction", kLive,
        [](auto& c) -> auto& { return c.zones.min_visible_fraction; }, ""));
    add(zonesKey());
    add(realKey(
        "calibration_health.interval_s", kLive,
        [](auto& c) -> auto& { return c.calibration_health.interval_s; }, "s"));
    add(boolKey(
        "calibration_health.withhold_when_failed", kLive,
        [](auto& c) -> auto& { return c.calibration_health.withhold_when_failed; }));

    add(textKey(
        "socket.path", kRestart, [](auto& c) -> auto& { return c.socket.path; }, true));
    add(modeKey());
    add(textKey(
        "socket.group", kRestart, [](auto& c) -> auto& { return c.socket.group; }, false));
    add(integerKey(
        "socket.max_clients", kRestart, [](auto& c) -> auto& { return c.socket.max_clients; }));
    add(integerKey(
        "socket.max_request_bytes", kRestart,
        [](auto& c) -> auto& { return c.socket.max_request_bytes; }));
    add(realKey(
        "socket.idle_timeout_s", kRestart, [](auto& c) -> auto& { return c.socket.idle_timeout_s; },
        "s"));
    add(idListKey(
        "socket.allow_uids", kRestart, [](auto& c) -> auto& { return c.socket.allow_uids; }));
    add(idListKey(
        "socket.allow_gids", kRestart, [](auto& c) -> auto& { return c.socket.allow_gids; }));

    add(realKey(
        "publish.readings_max_hz", kLive,
        [](auto& c) -> auto& { return c.publish.readings_max_hz; }, "Hz"));
    add(realKey(
        "publish.depth_max_hz", kLive, [](auto& c) -> auto& { return c.publish.depth_max_hz; },
        "Hz"));
    add(integerKey(
        "publish.max_client_backlog_bytes", kLive,
        [](auto& c) -> auto& { return c.publish.max_client_backlog_bytes; }));
    add(realKey(
        "publish.max_reading_age_ms", kLive,
        [](auto& c) -> auto& { return c.publish.max_reading_age_ms; }, "ms"));
    add(textKey(
        "log_level", kLive, [](auto& c) -> auto& { return c.log_level; }, false));
    return keys;
}

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

const Schema& schema()
{
    static const Schema instance = [] {
        Schema built;
        built.keys = buildKeyTable();
        for (const auto& def : built.keys) {
            SchemaNode* node = &built.root;
            size_t start = 0;
            while (true) {
                const size_t dot = def.path.find('.', start);
                const std::string part = def.path.substr(start, dot - start);
                SchemaNode* next = nullptr;
                for (auto& entry : node->children) {
                    if (entry.name == part) {
                        next = &entry;
                    }
                }
                if (next == nullptr) {
                    node->children.push_back(SchemaNode{part, nullptr, {}});
                    next = &node->children.back();
                }
                node = next;
                if (dot == std::string::npos) {
                    break;
                }
                start = dot + 1;
            }
            node->key = &def;
        }
        return built;
    }();
    return instance;
}

std::string joinPath(const std::string& prefix, std::string_view name)
{
    return prefix.empty() ? std::string(name) : prefix + "." + std::string(name);
}

// ---------------------------------------------------------------------------------------
// Reading a document

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
    std::string text;
};

std::vector<std::string> inLineOrder(std::vector<Problem> problems)
{
    std::stable_sort(problems.begin(), problems.end(), [](const Problem& a, const Problem& b) {
        const auto order = [](int line) {
            return line > 0 ? line : std::numeric_limits<int>::max();
        };
        return order(a.line) < order(b.line);
    });
    std::vector<std::string> texts;
    for (auto& problem : problems) {
        texts.push_back(std::move(problem.text));
    }
    return texts;
}

// Reads one parsed document into a configuration, noting every problem. One per call,
// thread-bound.
class DocumentReader {
  public:
    DocumentReader(std::string origin, ReadContext context, ServiceConfig& config,
                   KeyLocations& locations, std::vector<Problem>& problems)
        : origin_(std::move(origin)), context_(std::move(context)), config_(config),
          locations_(locations), problems_(problems)
    {
    }

    void read(const YAML::Node& root) { readSection(root, schema().root, "", root.Mark()); }

  private:
    void report(const YAML::Mark& mark, const std::string& key, std::string_view problem,
                std::string_view detail)
    {
        std::string message = origin_;
        if (!mark.is_null()) {
            message += ":" + std::to_string(mark.line + 1);
        }
        message += ": ";
        if (!key.empty()) {
            message += key + ": ";
        }
        message += problem;
        if (!detail.empty()) {
            message += " (" + std::string(detail) + ")";
        }
        problems_.push_back(Problem{mark.is_null() ? 0 : mark.line + 1, std::move(message)});
    }

    void readSection(const YAML::Node& node, const SchemaNode& section, const std::string& prefix,
                     const YAML::Mark& mark)
    {
        if (node.IsNull()) {
            return; // an empty section ("nearest:" and nothing under it) keeps the defaults
        }
        if (!node.IsMap()) {
            report(mark, prefix, prefix.empty() ? "not a mapping of keys" : "not a section",
                   "got " + describeNode(node) + ", expected a mapping of keys");
            locations_.unreadable.insert(prefix);
            return;
        }
        std::map<std::string, int> seen; // key -> line of its first appearance
        for (const auto& item : node) {
            // Copies: the iterator hands out temporaries (Nodes are handles, cheap to copy).
            const YAML::Node key_node = item.first;
            const YAML::Node value = item.second;
            const YAML::Mark key_mark = key_node.Mark();
            if (!key_node.IsScalar()) {
                report(key_mark, prefix, "a key that is not a name",
                       "got " + describeNode(key_node));
                continue;
            }
            const std::string& name = key_node.Scalar();
            const std::string path = joinPath(prefix, name);
            const auto [first, inserted] = seen.emplace(name, key_mark.line + 1);
            if (!inserted) {
                report(key_mark, path, "given twice",
                       "first on line " + std::to_string(first->second) + "; remove one");
                continue;
            }
            const SchemaNode* entry = section.child(name);
            if (entry == nullptr) {
                reportUnknownKey(key_mark, section, prefix, name);
                continue;
            }
            locations_.lines[path] = key_mark.line + 1;
            if (entry->key == nullptr) {
                readSection(value, *entry, path, key_mark);
                continue;
            }
            if (auto failure = entry->key->read(value, config_, context_)) {
                report(key_mark, path, failure->problem,
                       "got " + describeNode(value) + ", expected " + failure->expected);
                locations_.unreadable.insert(path);
            }
        }
    }

    void reportUnknownKey(const YAML::Mark& mark, const SchemaNode& section,
                          const std::string& prefix, const std::string& name)
    {
        std::vector<std::string> siblings;
        for (const auto& entry : section.children) {
            siblings.push_back(entry.name);
        }
        const std::string path = joinPath(prefix, name);
        if (auto suggestion = closestName(name, siblings)) {
            report(mark, path, "unknown key", "did you mean " + *suggestion + "?");
            return;
        }
        // A known key in the wrong section ("min_pixels" under "matcher").
        std::vector<std::string> elsewhere;
        for (const auto& def : schema().keys) {
            const size_t dot = def.path.rfind('.');
            const std::string leaf = dot == std::string::npos ? def.path : def.path.substr(dot + 1);
            if (normalizedName(leaf) == normalizedName(name)) {
                elsewhere.push_back(def.path);
            }
        }
        if (!elsewhere.empty()) {
            report(mark, path, "unknown key", "did you mean " + listNames(elsewhere) + "?");
            return;
        }
        report(mark, path, "unknown key", "known keys here: " + listNames(siblings));
    }

    std::string origin_;
    ReadContext context_;
    ServiceConfig& config_;
    KeyLocations& locations_;
    std::vector<Problem>& problems_;
};

// ---------------------------------------------------------------------------------------
// Validation

// A closed, open or half-open interval with its unit, for range checks and their messages.
struct Range {
    double lo = -std::numeric_limits<double>::infinity();
    double hi = std::numeric_limits<double>::infinity();
    bool lo_open = false;
    bool hi_open = false;
    std::string unit; // " m", " ms", ...: appended to the expected range

    bool contains(double value) const
    {
        return (lo_open ? value > lo : value >= lo) && (hi_open ? value < hi : value <= hi);
    }

    std::string text() const
    {
        if (std::isinf(hi)) {
            return (lo_open ? "> " : ">= ") + formatNumber(lo) + unit;
        }
        if (!lo_open && !hi_open) {
            return formatNumber(lo) + " to " + formatNumber(hi) + unit;
        }
        return (lo_open ? "> " : ">= ") + formatNumber(lo) + " and " + (hi_open ? "< " : "<= ") +
               formatNumber(hi) + unit;
    }
};

Range above(double lo, double hi, std::string unit)
{
    return Range{lo, hi, true, false, std::move(unit)};
}

Range closed(double lo, double hi, std::string unit)
{
    return Range{lo, hi, false, false, std::move(unit)};
}

// Checks the values of a configuration and words the problems. One per call,
// thread-bound.
class Checker {
  public:
    Checker(const ServiceConfig& config, const KeyLocations& locations)
        : config_(config), locations_(locations),
          origin_(config.origin.empty() ? "<config>" : config.origin)
    {
    }

    // Records a problem with `key` unless its value could not be read in the first place.
    void fail(const std::string& key, std::string_view problem, std::string_view expected)
    {
        if (locations_.unreadable.count(key) != 0) {
            return;
        }
        const KeyDef* def = schema().find(key);
        const std::string got = def != nullptr ? def->show(config_) : std::string("?");
        const auto line = locations_.lines.find(key);
        problems_.push_back(Problem{line != locations_.lines.end() ? line->second : 0,
                                    location(key) + ": " + key + ": " + std::string(problem) +
                                        " (got " + got + ", expected " + std::string(expected) +
                                        ")"});
        failed_.insert(key);
    }

    // True when none of `keys` has a problem yet: cross-key checks need good inputs.
    bool usable(std::initializer_list<std::string_view> keys) const
    {
        return std::none_of(keys.begin(), keys.end(), [&](std::string_view key) {
            const std::string name(key);
            return failed_.count(name) != 0 || locations_.unreadable.count(name) != 0;
        });
    }

    void real(const std::string& key, double value, const Range& range)
    {
        if (!std::isfinite(value)) {
            fail(key, "not a finite number", range.text());
        } else if (!range.contains(value)) {
            fail(key, "out of range", range.text());
        }
    }

    // hi at the limit of the field's type reads as no upper bound (">= 1 px").
    void integer(const std::string& key, int64_t value, int64_t lo, int64_t hi,
                 std::string_view unit = "")
    {
        if (value >= lo && value <= hi) {
            return;
        }
        const bool open =
            hi == std::numeric_limits<int>::max() || hi == std::numeric_limits<uint32_t>::max();
        fail(
            key, "out of range",
            (open ? ">= " + std::to_string(lo) : std::to_string(lo) + " to " + std::to_string(hi)) +
                std::string(unit));
    }

    std::vector<Problem> takeProblems() { return std::move(problems_); }

  private:
    std::string location(const std::string& key) const
    {
        if (auto it = locations_.overridden.find(key); it != locations_.overridden.end()) {
            return "command line (" + it->second + ")";
        }
        if (auto it = locations_.lines.find(key); it != locations_.lines.end()) {
            return origin_ + ":" + std::to_string(it->second);
        }
        return origin_;
    }

    const ServiceConfig& config_;
    const KeyLocations& locations_;
    std::string origin_;
    std::vector<Problem> problems_;
    std::set<std::string> failed_;
};

// A path the service will open: exists and has the right type. Relative paths are
// checked against the working directory, as the service will open them.
void checkPath(Checker& checker, const std::string& key, const std::string& path, bool directory,
               std::string_view expected)
{
    std::error_code error;
    const fs::file_status status = fs::status(path, error);
    if (status.type() == fs::file_type::not_found) {
        checker.fail(key, "does not exist", expected);
    } else if (error) {
        checker.fail(key, "cannot be checked: " + error.message(), expected);
    } else if (directory && !fs::is_directory(status)) {
        checker.fail(key, "is not a directory", expected);
    } else if (!directory && !fs::is_regular_file(status)) {
        checker.fail(key, "is not a regular file", expected);
    } else if (::access(path.c_str(), R_OK | (directory ? X_OK : 0)) != 0) {
        checker.fail(key, std::string("cannot be read: ") + std::strerror(errno), expected);
    }
}

void checkCameras(Checker& checker, const SourceConfig& source)
{
    const CamerasConfig& cameras = source.cameras;
    checker.integer("source.cameras.width", cameras.width, 16, 16384, " px");
    checker.integer("source.cameras.height", cameras.height, 16, 16384, " px");
    checker.real("source.cameras.fps", cameras.fps, above(0, 1000, " frames/s"));
    const CameraControls& controls = cameras.controls;
    if (controls.exposure_us) {
        checker.integer("source.cameras.controls.exposure_us", *controls.exposure_us, 1, 10000000,
                        " us");
    }
    if (controls.gain) {
        checker.integer("source.cameras.controls.gain", *controls.gain, 0,
                        std::numeric_limits<int>::max(), " (device units)");
    }
    if (controls.white_balance_k) {
        checker.integer("source.cameras.controls.white_balance_k", *controls.white_balance_k, 1000,
                        20000, " K");
    }
    if (cameras.lock_exposure && controls.auto_exposure.value_or(false)) {
        checker.fail("source.cameras.lock_exposure",
                     "contradicts source.cameras.controls.auto_exposure: true",
                     "false, or auto_exposure keep or false");
    }

    if (source.kind == SourceKind::V4l2) {
        constexpr std::string_view kDevice =
            "a V4L2 device path, e.g. /dev/v4l/by-id/usb-...-video-index0 (stereoctl devices "
            "lists them)";
        if (cameras.left.empty()) {
            checker.fail("source.cameras.left", "empty with source.type v4l2", kDevice);
        }
        if (cameras.right.empty()) {
            checker.fail("source.cameras.right", "empty with source.type v4l2", kDevice);
        }
        if (!cameras.left.empty() && cameras.left == cameras.right) {
            checker.fail("source.cameras.right", "the same device as source.cameras.left",
                         "the other camera of the rig");
        }
        // A partner more than half a period away may belong to the next frame: pairs
        // must not be able to mix up instants.
        const double half_period_ms = 500.0 / cameras.fps;
        if (checker.usable({"source.max_skew_ms", "source.cameras.fps"}) &&
            source.max_skew_ms >= half_period_ms) {
            checker.fail("source.max_skew_ms", "not below half the frame period",
                         "< " + formatNumber(half_period_ms) + " ms at source.cameras.fps " +
                             formatNumber(cameras.fps));
        }
    } else if (source.kind == SourceKind::SideBySide) {
        if (cameras.device.empty()) {
            checker.fail("source.cameras.device", "empty with source.type side_by_side",
                         "the V4L2 device path of the side-by-side camera");
        }
        if (cameras.width % 2 != 0) {
            checker.fail("source.cameras.width", "odd with source.type side_by_side",
                         "an even width: the frame holds two halves");
        }
    }
}

void checkSource(Checker& checker, const SourceConfig& source, const std::string& calibration)
{
    checker.integer("source.ring_capacity", source.ring_capacity, 2, 64, " pairs");
    checker.real("source.max_skew_ms", source.max_skew_ms, above(0, 1000, " ms"));
    // Shorter than 100 ms would call a 10 fps source down between two frames.
    checker.real("source.stall_timeout_ms", source.stall_timeout_ms, closed(100, 600000, " ms"));
    checker.real("source.replay.fps", source.replay.fps, above(0, 1000, " fps"));

    checkCameras(checker, source);

    constexpr std::string_view kRecording =
        "a recording directory (frames.csv, left/, right/), a folder of left*/right* images, "
        "or a ROS 2 bag (FILE.mcap)";
    constexpr std::string_view kCalibration = "a calibration file (docs/calibration.md)";
    if (!source.replay.path.empty()) {
        // A regular file must be an MCAP bag: it starts with MCAP's magic bytes.
        std::error_code error;
        if (fs::is_regular_file(source.replay.path, error)) {
            char magic[8] = {};
            std::ifstream(source.replay.path, std::ios::binary).read(magic, sizeof magic);
            if (std::string_view(magic, sizeof magic) != std::string_view("\x89MCAP0\r\n", 8)) {
                checker.fail("source.replay.path", "is neither a directory nor an MCAP file",
                             kRecording);
            }
        } else {
            checkPath(checker, "source.replay.path", source.replay.path, true, kRecording);
        }
    }
    // Without a calibration key the recording's own calibration.yaml is used; with
    // neither, the service runs uncalibrated (docs/service.md), which is no error.
    if (!calibration.empty()) {
        checkPath(checker, "calibration", calibration, false, kCalibration);
    }
}

// A refusal thrown by a part's own validation, "key: problem", as the checker's problem
// for that key (`fallback_key` when the message names none). A list item's key
// ("zones[1].max") belongs to the list's key, and the item is named in what is expected.
void failAsRefused(Checker& checker, const std::string& message, const std::string& fallback_key)
{
    const std::string docs = "see docs/configuration.md";
    const size_t colon = message.find(": ");
    if (colon == std::string::npos) {
        checker.fail(fallback_key, message, docs);
        return;
    }
    const std::string key = message.substr(0, colon);
    const size_t bracket = key.find('[');
    if (bracket != std::string::npos)
        checker.fail(key.substr(0, bracket), message.substr(colon + 2), key);
    else
        checker.fail(key, message.substr(colon + 2), docs);
}

// census-sgm's own limits are the matcher's (one place): its first refusal, by key.
void checkCensusSgm(Checker& checker, const MatcherSettings& matcher)
{
    try {
        validateCensusSgm(matcher);
    } catch (const std::invalid_argument& e) {
        failAsRefused(checker, e.what(), "matcher.algorithm");
    }
}

void checkMatcher(Checker& checker, const MatcherSettings& matcher)
{
    checker.real("matcher.min_depth_m", matcher.min_depth_m, above(0, 1000, " m"));

    // Cost grows linearly with the range; beyond 1024 px no rig in this service's reach
    // needs more, and OpenCV's buffers grow with it.
    constexpr int kMaxDisparities = 1024;
    const std::string steps = "16 to " + std::to_string(kMaxDisparities) + " in steps of 16";
    if (matcher.max_num_disparities % 16 != 0) {
        checker.fail("matcher.max_num_disparities", "not a multiple of 16", steps);
    } else {
        checker.integer("matcher.max_num_disparities", matcher.max_num_disparities, 16,
                        kMaxDisparities);
    }
    if (matcher.num_disparities != 0) {
        if (matcher.num_disparities % 16 != 0) {
            checker.fail("matcher.num_disparities", "not a multiple of 16", "auto or " + steps);
        } else if (matcher.num_disparities < 16 || matcher.num_disparities > kMaxDisparities) {
            checker.fail("matcher.num_disparities", "out of range", "auto or " + steps);
        }
    }
    checker.integer("matcher.min_disparity", matcher.min_disparity, -kMaxDisparities,
                    kMaxDisparities, " px");

    checker.integer("matcher.uniqueness_ratio", matcher.uniqueness_ratio, 0, 100, " percent");
    checker.integer("matcher.speckle_window_px", matcher.speckle_window_px, 0, 1000000, " px");
    checker.integer("matcher.speckle_range_px", matcher.speckle_range_px, 0, kMaxDisparities,
                    " px");
    if (matcher.lr_max_diff_px < -1 || matcher.lr_max_diff_px > kMaxDisparities) {
        checker.fail("matcher.lr_max_diff_px", "out of range",
                     "-1 (off) or 0 to " + std::to_string(kMaxDisparities) + " px");
    }

    if (matcher.kind == MatcherKind::CensusSgm) {
        if (checker.usable({"matcher.num_disparities", "matcher.max_num_disparities",
                            "matcher.min_disparity", "matcher.uniqueness_ratio",
                            "matcher.speckle_window_px", "matcher.speckle_range_px"}))
            checkCensusSgm(checker, matcher);
        return;
    }
    // OpenCV's limits: StereoBM takes odd blocks of 5..255, StereoSGBM odd blocks >= 1;
    // beyond 31 px SGBM only blurs depth edges and costs time.
    const bool bm = matcher.kind == MatcherKind::Bm;
    const int block_lo = bm ? 5 : 1;
    const int block_hi = bm ? 255 : 31;
    const std::string block_expected = "an odd number from " + std::to_string(block_lo) + " to " +
                                       std::to_string(block_hi) + " px for " +
                                       algorithmName(matcher);
    if (matcher.block_size % 2 == 0) {
        checker.fail("matcher.block_size", "not odd", block_expected);
    } else if (matcher.block_size < block_lo || matcher.block_size > block_hi) {
        checker.fail("matcher.block_size", "out of range", block_expected);
    }

    // SGBM keeps its path costs in 16 bits, so penalties stay below 32768.
    constexpr int kMaxPenalty = 32767;
    if (matcher.p1 != 0) {
        checker.integer("matcher.p1", matcher.p1, 1, kMaxPenalty);
    }
    if (matcher.p2 != 0) {
        checker.integer("matcher.p2", matcher.p2, 1, kMaxPenalty);
    }
    if (!bm && checker.usable({"matcher.p1", "matcher.p2", "matcher.block_size"})) {
        // The automatic penalties, for one (grayscale) channel: 8*bs^2 and 32*bs^2.
        const int area = matcher.block_size * matcher.block_size;
        const int p1 = matcher.p1 != 0 ? matcher.p1 : 8 * area;
        const int p2 = matcher.p2 != 0 ? matcher.p2 : 32 * area;
        if (p2 <= p1) {
            if (matcher.p2 != 0) {
                checker.fail("matcher.p2", "not above matcher.p1",
                             "> " + std::to_string(p1) +
                                 (matcher.p1 != 0 ? "" : ", the automatic p1 of 8*block_size^2"));
            } else {
                checker.fail("matcher.p1", "not below the automatic p2",
                             "< " + std::to_string(p2) + " (32*block_size^2), or set matcher.p2");
            }
        }
    }
    checker.integer("matcher.pre_filter_cap", matcher.pre_filter_cap, 1, 63);
    checker.integer("matcher.texture_threshold", matcher.texture_threshold, 0,
                    std::numeric_limits<int>::max());
}

void checkNearest(Checker& checker, const NearestSettings& nearest)
{
    const RegionOfInterest& roi = nearest.roi;
    checker.real("nearest.roi.x", roi.x, Range{0, 1, false, true, " of the image width"});
    checker.real("nearest.roi.y", roi.y, Range{0, 1, false, true, " of the image height"});
    checker.real("nearest.roi.width", roi.width, above(0, 1, " of the image width"));
    checker.real("nearest.roi.height", roi.height, above(0, 1, " of the image height"));
    // A tolerance for fractions such as 0.3 + 0.7 that do not add up to 1 exactly.
    constexpr double kSlack = 1e-9;
    if (checker.usable({"nearest.roi.x", "nearest.roi.width"}) && roi.x + roi.width > 1 + kSlack) {
        checker.fail("nearest.roi.width", "reaches past the right edge of the image",
                     "<= " + formatNumber(1 - roi.x) + ", 1 - nearest.roi.x");
    }
    if (checker.usable({"nearest.roi.y", "nearest.roi.height"}) &&
        roi.y + roi.height > 1 + kSlack) {
        checker.fail("nearest.roi.height", "reaches past the bottom edge of the image",
                     "<= " + formatNumber(1 - roi.y) + ", 1 - nearest.roi.y");
    }

    checker.real("nearest.min_depth_m", nearest.min_depth_m, above(0, 1000, " m"));
    checker.real("nearest.max_depth_m", nearest.max_depth_m, above(0, 1000, " m"));
    if (checker.usable({"nearest.min_depth_m", "nearest.max_depth_m"}) &&
        nearest.max_depth_m <= nearest.min_depth_m) {
        checker.fail("nearest.max_depth_m", "not above nearest.min_depth_m",
                     "> " + formatNumber(nearest.min_depth_m) + " m");
    }
    checker.real("nearest.percentile", nearest.percentile, closed(0, 100, " percent"));
    checker.real("nearest.min_valid_fraction", nearest.min_valid_fraction,
                 closed(0, 1, " of the region's pixels"));
    checker.integer("nearest.min_pixels", nearest.min_pixels, 1, std::numeric_limits<int>::max(),
                    " px");
    checker.real("nearest.min_in_range_fraction", nearest.min_in_range_fraction,
                 closed(0, 1, " of the region's pixels"));
    checker.integer("nearest.min_confidence", nearest.min_confidence, 0, 255, "");
    checker.real("nearest.range_limit_fraction", nearest.range_limit_fraction,
                 closed(0, 1, " of the region's pixels"));
}

void checkSocket(Checker& checker, const SocketConfig& socket)
{
    // sockaddr_un holds the path with its terminating NUL.
    constexpr size_t kMaxPath = sizeof(sockaddr_un::sun_path) - 1;
    if (socket.path.empty()) {
        checker.fail("socket.path", "empty", "the path of the service's Unix socket");
    } else if (socket.path.size() > kMaxPath) {
        checker.fail("socket.path", "too long for a Unix socket",
                     "at most " + std::to_string(kMaxPath) + " bytes");
    }
    if (socket.mode > 0777) {
        checker.fail("socket.mode", "out of range", "permission bits \"0000\" to \"0777\"");
    }
    if (!socket.group.empty()) {
        const bool numeric = std::all_of(socket.group.begin(), socket.group.end(),
                                         [](unsigned char ch) { return std::isdigit(ch); });
        if (!numeric) {
            // getgrnam_r, not getgrnam: validation may run on any thread.
            struct group entry {};
            struct group* found = nullptr;
            std::vector<char> buffer(16384);
            const int error =
                ::getgrnam_r(socket.group.c_str(), &entry, buffer.data(), buffer.size(), &found);
            if (error != 0) {
                checker.fail("socket.group",
                             std::string("cannot be looked up: ") + std::strerror(error),
                             "a group of this system");
            } else if (found == nullptr) {
                checker.fail("socket.group", "no such group", "a group of this system, or empty");
            }
        }
    }
    checker.integer("socket.max_clients", socket.max_clients, 1, 1024);
    checker.integer("socket.max_request_bytes", socket.max_request_bytes, 1024, 16 << 20, " bytes");
    checker.real("socket.idle_timeout_s", socket.idle_timeout_s,
                 closed(0, 86400, " s (0: no limit)"));
}

void checkPublish(Checker& checker, const PublishConfig& publish)
{
    checker.real("publish.readings_max_hz", publish.readings_max_hz,
                 closed(0, 1000, " Hz (0: every frame)"));
    checker.real("publish.depth_max_hz", publish.depth_max_hz,
                 closed(0, 1000, " Hz (0: every frame)"));
    // Below 1 MiB a single depth frame of a small camera would not fit.
    checker.integer("publish.max_client_backlog_bytes", publish.max_client_backlog_bytes, 1 << 20,
                    std::numeric_limits<uint32_t>::max(), " bytes");
    checker.real("publish.max_reading_age_ms", publish.max_reading_age_ms,
                 above(0, 3600000, " ms"));
}

std::vector<Problem> checkValues(const ServiceConfig& config, const KeyLocations& locations)
{
    Checker checker(config, locations);
    checkSource(checker, config.source, config.calibration_path);
    checkMatcher(checker, config.processing.matcher);
    checkNearest(checker, config.processing.nearest);
    checker.real("calibration_health.interval_s", config.calibration_health.interval_s,
                 closed(0, 3600, " s"));
    checker.real("robot.min_visible_fraction", config.zones.min_visible_fraction,
                 closed(0, 1, " of a zone's volume"));
    try {
        validateZonesSettings(config.zones);
    } catch (const std::invalid_argument& e) {
        failAsRefused(checker, e.what(), "zones");
    }
    checkSocket(checker, config.socket);
    checkPublish(checker, config.publish);
    const auto& levels = logLevelNames();
    if (std::find(levels.begin(), levels.end(), config.log_level) == levels.end()) {
        checker.fail("log_level", "unknown level", expectedOneOf(levels, config.log_level));
    }
    return checker.takeProblems();
}

// ---------------------------------------------------------------------------------------
// Loading

std::string absolutePath(const std::string& path)
{
    std::error_code error;
    const fs::path absolute = fs::absolute(path, error);
    return error ? path : absolute.lexically_normal().string();
}

// Applies the overrides and notes which option set which key.
void overrideKeys(ServiceConfig& config, const ConfigOverrides& overrides, KeyLocations& locations)
{
    const auto apply = [&](const std::string& value, std::string& field, const std::string& key,
                           const char* option, bool is_path) {
        if (value.empty()) {
            return;
        }
        field = is_path ? absolutePath(value) : value;
        locations.lines.erase(key);
        locations.unreadable.erase(key);
        locations.overridden[key] = option;
    };
    apply(overrides.replay_path, config.source.replay.path, "source.replay.path", "--replay", true);
    if (!overrides.replay_path.empty()) {
        // --replay replaces the configured source, cameras included.
        config.source.kind = SourceKind::Replay;
        locations.lines.erase("source.type");
        locations.overridden["source.type"] = "--replay";
    }
    apply(overrides.calibration_path, config.calibration_path, "calibration", "--calib", true);
    apply(overrides.socket_path, config.socket.path, "socket.path", "--socket", true);
    apply(overrides.log_level, config.log_level, "log_level", "--log-level", false);
}

// Notes where the second document of a stream starts, and ignores everything else.
class SecondDocumentFinder final : public YAML::EventHandler {
  public:
    void OnDocumentStart(const YAML::Mark& mark) override
    {
        if (++documents_ == 2) {
            second_ = mark;
        }
    }
    void OnDocumentEnd() override {}
    void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
    void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
    void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  const std::string&) override
    {
    }
    void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                         YAML::EmitterStyle::value) override
    {
    }
    void OnSequenceEnd() override {}
    void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                    YAML::EmitterStyle::value) override
    {
    }
    void OnMapEnd() override {}

    std::optional<YAML::Mark> second() const
    {
        return documents_ >= 2 ? std::optional<YAML::Mark>(second_) : std::nullopt;
    }

  private:
    int documents_ = 0;
    YAML::Mark second_ = YAML::Mark::null_mark();
};

// Where a second document starts, if the text has one. yaml-cpp 0.7's LoadAll() never
// returns on some malformed input (found by fuzzing: its parser keeps producing
// documents), so the first document is loaded with Load() and a second one is only
// looked for, with at most two steps of the parser.
std::optional<YAML::Mark> secondDocumentStart(const std::string& text)
{
    std::istringstream stream(text);
    YAML::Parser parser(stream);
    SecondDocumentFinder finder;
    for (int document = 0; document < 2 && parser.HandleNextDocument(finder); ++document) {
    }
    return finder.second();
}

ServiceConfig parseDocument(const std::string& text, const std::string& origin,
                            const ReadContext& context, const ConfigOverrides& overrides)
{
    ServiceConfig config = defaultConfig();
    config.origin = origin;
    KeyLocations locations;
    std::vector<Problem> problems;
    try {
        DocumentReader(origin, context, config, locations, problems).read(YAML::Load(text));
        if (const auto mark = secondDocumentStart(text)) {
            const int line = mark->is_null() ? 0 : mark->line + 1;
            problems.push_back(Problem{line, origin + (line > 0 ? ":" + std::to_string(line) : "") +
                                                 ": a second YAML document (expected one; "
                                                 "remove the \"---\")"});
        }
    } catch (const YAML::Exception& error) {
        // Syntax errors (ParserException) and anything else yaml-cpp refuses.
        std::string message = origin;
        if (!error.mark.is_null()) {
            message += ":" + std::to_string(error.mark.line + 1);
        }
        message += ": YAML syntax error";
        if (!error.mark.is_null()) {
            message += " at column " + std::to_string(error.mark.column + 1);
        }
        problems.push_back(Problem{0, message + ": " + error.msg});
        throw ConfigError(inLineOrder(std::move(problems)));
    }
    // A file that chooses census-sgm gets census-sgm's own values for the settings it
    // shares with OpenCV's matchers, where the file does not set them.
    if (config.processing.matcher.kind == MatcherKind::CensusSgm) {
        MatcherSettings tuned = config.processing.matcher;
        applyCensusSgmDefaults(tuned);
        MatcherSettings& m = config.processing.matcher;
        const auto unset = [&](const char* key) { return locations.lines.count(key) == 0; };
        if (unset("matcher.uniqueness_ratio"))
            m.uniqueness_ratio = tuned.uniqueness_ratio;
        if (unset("matcher.lr_max_diff_px"))
            m.lr_max_diff_px = tuned.lr_max_diff_px;
        if (unset("matcher.speckle_window_px"))
            m.speckle_window_px = tuned.speckle_window_px;
        if (unset("matcher.speckle_range_px"))
            m.speckle_range_px = tuned.speckle_range_px;
    }
    overrideKeys(config, overrides, locations);
    auto value_problems = checkValues(config, locations);
    problems.insert(problems.end(), std::make_move_iterator(value_problems.begin()),
                    std::make_move_iterator(value_problems.end()));
    if (!problems.empty()) {
        throw ConfigError(inLineOrder(std::move(problems)));
    }
    return config;
}

std::string readConfigFile(const std::string& path)
{
    // A configuration is a few kilobytes; a large file is the wrong file.
    constexpr long kMaxBytes = 1 << 20;
    std::error_code error;
    if (fs::is_directory(path, error)) {
        throw ConfigError({path + ": cannot read the configuration: is a directory"});
    }
    std::FILE* file = std::fopen(path.c_str(), "rb");
    if (file == nullptr) {
        throw ConfigError({path + ": cannot read the configuration: " + std::strerror(errno)});
    }
    std::string text;
    char buffer[8192];
    size_t count = 0;
    while ((count = std::fread(buffer, 1, sizeof buffer, file)) > 0) {
        text.append(buffer, count);
        if (static_cast<long>(text.size()) > kMaxBytes) {
            std::fclose(file);
            throw ConfigError({path + ": cannot read the configuration: larger than 1 MiB"});
        }
    }
    const bool failed = std::ferror(file) != 0;
    const int read_errno = errno;
    std::fclose(file);
    if (failed) {
        throw ConfigError({path + ": cannot read the configuration: " + std::strerror(read_errno)});
    }
    return text;
}

} // namespace

ConfigError::ConfigError(std::vector<std::string> problems)
    : std::runtime_error(problems.empty() ? std::string("invalid configuration")
                                          : joinLines(problems)),
      problems_(std::move(problems))
{
}

ServiceConfig defaultConfig()
{
    ServiceConfig config;
    config.origin = "<defaults>";
    return config;
}

ServiceConfig loadConfig(const std::string& path)
{
    return loadConfig(path, ConfigOverrides{});
}

ServiceConfig loadConfig(const std::string& path, const ConfigOverrides& overrides)
{
    const std::string text = readConfigFile(path);
    ReadContext context;
    context.base_dir = fs::path(absolutePath(path)).parent_path();
    return parseDocument(text, path, context, overrides);
}

ServiceConfig parseConfig(const std::string& yaml_text, const std::string& origin)
{
    return parseDocument(yaml_text, origin, ReadContext{}, ConfigOverrides{});
}

void applyOverrides(ServiceConfig& config, const ConfigOverrides& overrides)
{
    KeyLocations unused;
    overrideKeys(config, overrides, unused);
}

void validateConfig(const ServiceConfig& config)
{
    auto problems = checkValues(config, KeyLocations{});
    if (!problems.empty()) {
        throw ConfigError(inLineOrder(std::move(problems)));
    }
}

ConfigChange diffConfig(const ServiceConfig& running, const ServiceConfig& proposed)
{
    ConfigChange change;
    for (const auto& def : schema().keys) {
        if (def.show(running) != def.show(proposed)) {
            change.changed.push_back(def.path);
            if (!def.live) {
                change.restart_needed.push_back(def.path);
            }
        }
    }
    return change;
}

std::vector<ConfigKeyInfo> configKeys()
{
    std::vector<ConfigKeyInfo> keys;
    for (const auto& def : schema().keys) {
        keys.push_back(ConfigKeyInfo{def.path, def.live});
    }
    return keys;
}

} // namespace stereod
