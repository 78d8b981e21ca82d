#include "protocol/json_writer.hpp"

#include <array>
#include <charconv>
#include <cmath>

namespace stereod {

namespace {

// Length of the well-formed UTF-8 sequence starting at text[i], or 0 when the bytes there
// are not one (overlong forms, surrogates and code points above U+10FFFF included).
std::size_t utf8SequenceLength(std::string_view text, std::size_t i) noexcept
{
    const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(text[k]); };
    const unsigned char lead = byte(i);
    const std::size_t left = text.size() - i;
    const auto continuation = [&](std::size_t k) { return (byte(k) & 0xC0u) == 0x80u; };
    if (lead < 0x80u)
        return 1;
    if (lead >= 0xC2u && lead <= 0xDFu)
        return left >= 2 && continuation(i + 1) ? 2 : 0;
    if (lead >= 0xE0u && lead <= 0xEFu) {
        if (left < 3 || !continuation(i + 1) || !continuation(i + 2))
            return 0;
        if (lead == 0xE0u && byte(i + 1) < 0xA0u)
            return 0; // overlong
        if (lead == 0xEDu && byte(i + 1) >= 0xA0u)
            return 0; // UTF-16 surrogate
        return 3;
    }
    if (lead >= 0xF0u && lead <= 0xF4u) {
        if (left < 4 || !continuation(i + 1) || !continuation(i + 2) || !continuation(i + 3))
            return 0;
        if (lead == 0xF0u && byte(i + 1) < 0x90u)
            return 0; // overlong
        if (lead == 0xF4u && byte(i + 1) >= 0x90u)
            return 0; // above U+10FFFF
        return 4;
    }
    return 0;
}

} // namespace

void appendJsonString(std::string& out, std::string_view text)
{
    static constexpr char kHex[] = "0123456789abcdef";
    out.push_back('"');
    std::size_t i = 0;
    while (i < text.size()) {
        const auto c = static_cast<unsigned char>(text[i]);
        switch (c) {
        case '"':
            out.append("\\\"");
            ++i;
            continue;
        case '\\':
            out.append("\\\\");
            ++i;
            continue;
        case '\n':
            out.append("\\n");
            ++i;
            continue;
        case '\r':
            out.append("\\r");
            ++i;
            continue;
        case '\t':
            out.append("\\t");
            ++i;
            continue;
        default:
            break;
        }
        if (c < 0x20u) {
            const char escaped[] = {'\\', 'u', '0', '0', kHex[c >> 4], kHex[c & 0xFu]};
            out.append(escaped, sizeof escaped);
            ++i;
            continue;
        }
        const std::size_t length = utf8SequenceLength(text, i);
        if (length == 0) {
            out.append("\xEF\xBF\xBD"); // U+FFFD REPLACEMENT CHARACTER
            ++i;
            continue;
        }
        out.append(text.substr(i, length));
        i += length;
    }
    out.push_back('"');
}

void appendJsonNumber(std::string& out, double value)
{
    if (!std::isfinite(value)) {
        out.append("null");
        return;
    }
    std::array<char, 32> buffer{};
    const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
    out.append(buffer.data(), result.ptr);
}

void appendJsonNumber(std::string& out, int64_t value)
{
    std::array<char, 24> buffer{};
    const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
    out.append(buffer.data(), result.ptr);
}

void appendJsonNumber(std::string& out, uint64_t value)
{
    std::array<char, 24> buffer{};
    const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
    out.append(buffer.data(), result.ptr);
}

double roundTo(double value, int decimals) noexcept
{
    if (!std::isfinite(value))
        return value;
    const double scale = std::pow(10.0, decimals);
    const double rounded = std::round(value * scale) / scale;
    // Values too large to scale keep their own precision.
    return std::isfinite(rounded) ? rounded : value;
}

JsonObjectWriter::JsonObjectWriter(std::string& out) : out_(out)
{
    out_.push_back('{');
}

void JsonObjectWriter::key(std::string_view key)
{
    if (!first_)
        out_.push_back(',');
    first_ = false;
    out_.push_back('"');
    out_.append(key);
    out_.append("\":");
}

JsonObjectWriter& JsonObjectWriter::field(std::string_view key_text, double value)
{
    key(key_text);
    appendJsonNumber(out_, value);
    return *this;
}

JsonObjectWriter& JsonObjectWriter::field(std::string_view key_text, int64_t value)
{
    key(key_text);
    appendJsonNumber(out_, value);
    return *this;
}

JsonObjectWriter& JsonObjectWriter::field(std::string_view key_text, uint64_t value)
{
    key(key_text);
    appendJsonNumber(out_, value);
    return *this;
}

JsonObjectWriter& JsonObjectWriter::field(std::string_view key_text, uint32_t value)
{
    return field(key_text, static_cast<uint64_t>(value));
}

JsonObjectWriter& JsonObjectWriter::field(std::string_view key_text, int value)
{
    return field(key_text, static_cast<int64_t>(value));
}

JsonObjectWriter& JsonObjectWriter::field(std::string_view key_text, bool value)
{
    key(key_text);
    out_.append(value ? "true" : "false");
    return *this;
}

JsonObjectWriter& JsonObjectWriter::field(std::string_view key_text, std::string_view value)
{
    key(key_text);
    appendJsonString(out_, value);
    return *this;
}

JsonObjectWriter& JsonObjectWriter::field(std::string_view key_text, const char* value)
{
    return field(key_text, std::string_view(value));
}

JsonObjectWriter& JsonObjectWriter::nullField(std::string_view key_text)
{
    key(key_text);
    out_.append("null");
    return *this;
}

JsonObjectWriter& JsonObjectWriter::rawField(std::string_view key_text, std::string_view json_text)
{
    key(key_text);
    out_.append(json_text);
    return *this;
}

std::string& JsonObjectWriter::openField(std::string_view key_text)
{
    key(key_text);
    return out_;
}

void JsonObjectWriter::close()
{
    out_.push_back('}');
}

} // namespace stereod
