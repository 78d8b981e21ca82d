#pragma once
// Writes JSON text straight into a caller's std::string, for the lines the service sends
// every frame (reading and depth events): appending to a buffer that keeps its capacity
// allocates nothing in steady state, where building an nlohmann::json object would
// allocate a node per field. Replies to requests, which are rare, use nlohmann::json.
//
// Reentrant: a JsonObjectWriter borrows its string for its lifetime; distinct writers on
// distinct strings may run on any threads.

#include <cstdint>
#include <string>
#include <string_view>

namespace stereod {

// Appends `text` as a JSON string literal: quotes, backslashes and control characters
// escaped; bytes that are not valid UTF-8 replaced by U+FFFD, so the output is always
// valid JSON whatever the input (an exception text, a file name, a client's bytes).
void appendJsonString(std::string& out, std::string_view text);

// Appends a number in the shortest form that reads back to the same double; NaN and
// infinities (which JSON cannot hold) are written as null.
void appendJsonNumber(std::string& out, double value);
void appendJsonNumber(std::string& out, int64_t value);
void appendJsonNumber(std::string& out, uint64_t value);

// `value` rounded to `decimals` places (for output meant to be read by people too).
double roundTo(double value, int decimals) noexcept;

// One JSON object being written: `{` at construction, `}` at close(); fields are
// separated by commas as they come. Keys are trusted program constants, written as is.
class JsonObjectWriter {
  public:
    explicit JsonObjectWriter(std::string& out);

    JsonObjectWriter& field(std::string_view key, double value);
    JsonObjectWriter& field(std::string_view key, int64_t value);
    JsonObjectWriter& field(std::string_view key, uint64_t value);
    JsonObjectWriter& field(std::string_view key, uint32_t value);
    JsonObjectWriter& field(std::string_view key, int value);
    JsonObjectWriter& field(std::string_view key, bool value);
    JsonObjectWriter& field(std::string_view key, std::string_view value);
    JsonObjectWriter& field(std::string_view key, const char* value);
    JsonObjectWriter& nullField(std::string_view key);
    // A field whose value is JSON text the caller vouches for (a nested object).
    JsonObjectWriter& rawField(std::string_view key, std::string_view json_text);
    // Starts a field whose value the caller writes next (e.g. a nested writer).
    std::string& openField(std::string_view key);

    void close();

  private:
    void key(std::string_view key);

    std::string& out_;
    bool first_ = true;
};

} // namespace stereod
