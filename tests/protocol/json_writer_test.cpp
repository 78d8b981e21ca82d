// The direct JSON writer: numbers, strings escaped and made valid UTF-8, rounding.

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "protocol/json_writer.hpp"
#include "protocol/reply.hpp"

namespace stereod {
namespace {

TEST(JsonWriter, NumbersAndStrings)
{
    std::string out;
    appendJsonNumber(out, std::numeric_limits<double>::infinity());
    out.push_back(' ');
    appendJsonNumber(out, std::nan(""));
    out.push_back(' ');
    appendJsonNumber(out, 0.1);
    out.push_back(' ');
    appendJsonNumber(out, int64_t{-9'000'000'000'000'000'000});
    EXPECT_EQ(out, "null null 0.1 -9000000000000000000");

    // Valid multi-byte sequences pass; overlong forms, surrogates and truncated ones do not.
    out.clear();
    appendJsonString(out, "\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x98\x80 \xC0\xAF \xED\xA0\x80 \xE2\x82");
    EXPECT_EQ(out, "\"\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x98\x80 \xEF\xBF\xBD\xEF\xBF\xBD "
                   "\xEF\xBF\xBD\xEF\xBF\xBD\xEF\xBF\xBD \xEF\xBF\xBD\xEF\xBF\xBD\"");
    EXPECT_TRUE(Json::accept(out)) << out;
    EXPECT_DOUBLE_EQ(roundTo(37.20000001, 3), 37.2);
    EXPECT_DOUBLE_EQ(roundTo(1e300, 3), 1e300);
}

} // namespace
} // namespace stereod
