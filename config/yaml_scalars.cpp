#include "config/yaml_scalars.hpp"

#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include <yaml-cpp/yaml.h>

namespace stereod::config_detail {

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

namespace {

std::string_view withoutPlus(std::string_view text)
{
    if (text.size() > 1 && text.front() == '+' && text[1] != '-') {
        text.remove_prefix(1);
    }
    return text;
}

} // namespace

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

std::string_view scalarText(const YAML::Node& node)
{
    return node.IsScalar() ? std::string_view(node.Scalar()) : std::string_view();
}
} // namespace stereod::config_detail
