// The request parser without sockets, on good and bad input (docs/protocol.md).

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "protocol/request.hpp"

namespace stereod {
namespace {

Request parseOk(std::string_view line)
{
    ParseResult result = parseRequest(line);
    if (const auto* error = std::get_if<ProtocolError>(&result))
        ADD_FAILURE() << "\"" << line << "\" refused: " << errorCodeName(error->code) << ": "
                      << error->message;
    return std::holds_alternative<Request>(result) ? std::get<Request>(result) : Request{};
}

ProtocolError parseError(std::string_view line)
{
    ParseResult result = parseRequest(line);
    if (std::holds_alternative<Request>(result)) {
        ADD_FAILURE() << "\"" << line << "\" accepted";
        return {};
    }
    return std::get<ProtocolError>(result);
}

TEST(ProtocolParse, KnownCommands)
{
    EXPECT_TRUE(std::holds_alternative<HelloRequest>(parseOk(R"({"cmd":"hello"})").command));
    EXPECT_TRUE(std::holds_alternative<StatusRequest>(parseOk(R"({"cmd":"status"})").command));
    EXPECT_TRUE(std::holds_alternative<ReloadRequest>(parseOk(R"({"cmd":"reload"})").command));

    const Request distance = parseOk(R"({"cmd":"distance","max_age_ms":250.5})");
    ASSERT_TRUE(std::holds_alternative<DistanceRequest>(distance.command));
    EXPECT_DOUBLE_EQ(std::get<DistanceRequest>(distance.command).max_age_ms.value_or(0), 250.5);
    EXPECT_FALSE(std::get<DistanceRequest>(parseOk(R"({"cmd":"distance"})").command).max_age_ms);
    // null counts as absent.
    EXPECT_FALSE(
        std::get<DistanceRequest>(parseOk(R"({"cmd":"distance","max_age_ms":null})").command)
            .max_age_ms);

    const Request subscribe = parseOk(R"({"cmd":"subscribe","stream":"depth","max_hz":5})");
    ASSERT_TRUE(std::holds_alternative<SubscribeRequest>(subscribe.command));
    EXPECT_EQ(std::get<SubscribeRequest>(subscribe.command).stream, StreamKind::Depth);
    EXPECT_DOUBLE_EQ(std::get<SubscribeRequest>(subscribe.command).max_hz.value_or(0), 5.0);
    EXPECT_EQ(
        std::get<SubscribeRequest>(parseOk(R"({"cmd":"subscribe","stream":"readings"})").command)
            .stream,
        StreamKind::Readings);
}

TEST(ProtocolParse, RawFramesAndCalibration)
{
    EXPECT_TRUE(
        std::holds_alternative<CalibrationRequest>(parseOk(R"({"cmd":"calibration"})").command));
    EXPECT_TRUE(std::holds_alternative<ViewRequest>(parseOk(R"({"cmd":"view"})").command));
    const Request raw = parseOk(R"({"cmd":"subscribe","stream":"raw","max_hz":2})");
    ASSERT_TRUE(std::holds_alternative<SubscribeRequest>(raw.command));
    EXPECT_EQ(std::get<SubscribeRequest>(raw.command).stream, StreamKind::Raw);
    EXPECT_DOUBLE_EQ(std::get<SubscribeRequest>(raw.command).max_hz.value_or(0), 2.0);
    const Request snapshot = parseOk(R"({"cmd":"snapshot","items":["raw_right","raw_left"]})");
    ASSERT_TRUE(std::holds_alternative<SnapshotRequest>(snapshot.command));
    const std::vector<SnapshotItem> expected = {SnapshotItem::RawRight, SnapshotItem::RawLeft};
    EXPECT_EQ(std::get<SnapshotRequest>(snapshot.command).items, expected);
    // The default stays the processed result's four items.
    EXPECT_EQ(std::get<SnapshotRequest>(parseOk(R"({"cmd":"snapshot"})").command).items.size(), 4u);
    // A recorder asks for each pair's depth and cloud in the raw event.
    const SubscribeRequest with = std::get<SubscribeRequest>(
        parseOk(R"({"cmd":"subscribe","stream":"raw","with":["cloud","depth"]})").command);
    EXPECT_TRUE(with.with_depth);
    EXPECT_TRUE(with.with_cloud);
    const SubscribeRequest depth_only = std::get<SubscribeRequest>(
        parseOk(R"({"cmd":"subscribe","stream":"raw","with":["depth"]})").command);
    EXPECT_TRUE(depth_only.with_depth);
    EXPECT_FALSE(depth_only.with_cloud);
    EXPECT_FALSE(depth_only.with_colour);
    // And the cameras' colour with the frames.
    const SubscribeRequest colour = std::get<SubscribeRequest>(
        parseOk(R"({"cmd":"subscribe","stream":"raw","with":["colour"]})").command);
    EXPECT_TRUE(colour.with_colour);
    EXPECT_FALSE(colour.with_cloud);
    const Request colours = parseOk(
        R"({"cmd":"snapshot","items":["left_colour","cloud_colour","raw_left_colour","raw_right_colour"]})");
    const std::vector<SnapshotItem> colour_items = {
        SnapshotItem::LeftColour, SnapshotItem::CloudColour, SnapshotItem::RawLeftColour,
        SnapshotItem::RawRightColour};
    EXPECT_EQ(std::get<SnapshotRequest>(colours.command).items, colour_items);
}

TEST(ProtocolParse, SnapshotItemsKeepTheirOrderWithoutRepeats)
{
    const auto items = [](std::string_view line) {
        return std::get<SnapshotRequest>(parseOk(line).command).items;
    };
    EXPECT_EQ(items(R"({"cmd":"snapshot"})"),
              (std::vector<SnapshotItem>{SnapshotItem::Depth, SnapshotItem::Disparity,
                                         SnapshotItem::Left, SnapshotItem::Cloud}));
    EXPECT_EQ(items(R"({"cmd":"snapshot","items":["cloud","left","cloud"]})"),
              (std::vector<SnapshotItem>{SnapshotItem::Cloud, SnapshotItem::Left}));
    EXPECT_TRUE(items(R"({"cmd":"snapshot","items":[]})").empty());
}

TEST(ProtocolParse, IdIsEchoedAsGiven)
{
    EXPECT_EQ(parseOk(R"({"cmd":"hello","id":42})").id, Json(42));
    EXPECT_EQ(parseOk(R"({"id":{"seq":[1,"a"]},"cmd":"hello"})").id,
              Json::parse(R"({"seq":[1,"a"]})"));
    EXPECT_EQ(parseOk(R"({"cmd":"hello","id":null})").id, Json(nullptr));
    EXPECT_FALSE(parseOk(R"({"cmd":"hello"})").id.has_value());
    // An error reply still carries the id when the line had one.
    EXPECT_EQ(parseError(R"({"cmd":"fly","id":"x7"})").id, Json("x7"));
}

TEST(ProtocolParse, UnknownFieldsAndWhitespaceAreAccepted)
{
    EXPECT_TRUE(std::holds_alternative<HelloRequest>(
        parseOk("  {\"cmd\" : \"hello\", \"future_field\": [1, 2]}\r").command));
}

TEST(ProtocolParse, NotJsonIsBadJson)
{
    for (const std::string_view line :
         {std::string_view(""), std::string_view("hello"), std::string_view("{\"cmd\":"),
          std::string_view("{\"cmd\":\"hello\"} trailing"), std::string_view("{'cmd':'hello'}"),
          std::string_view("\x00\x01\x02", 3)}) {
        const ProtocolError error = parseError(line);
        EXPECT_EQ(error.code, ErrorCode::BadJson) << line;
        EXPECT_FALSE(error.message.empty());
    }
}

TEST(ProtocolParse, NonObjectIsBadJson)
{
    for (const char* line : {"[1,2]", "\"hello\"", "42", "null", "true"}) {
        const ProtocolError error = parseError(line);
        EXPECT_EQ(error.code, ErrorCode::BadJson) << line;
        EXPECT_NE(error.message.find("JSON object"), std::string::npos) << error.message;
    }
}

TEST(ProtocolParse, NonUtf8BytesAreBadJsonWithAValidReply)
{
    const std::string line = "{\"cmd\":\"hel\xff\xfe\"}";
    const ProtocolError error = parseError(line);
    EXPECT_EQ(error.code, ErrorCode::BadJson);
    // The library quotes the bytes it read; the reply line must still be valid UTF-8.
    std::string reply;
    appendJsonLine(reply, errorReply(error.code, error.message, error.id));
    EXPECT_TRUE(Json::accept(reply)) << reply;
}

TEST(ProtocolParse, MissingOrMistypedCmdIsBadRequest)
{
    const ProtocolError missing = parseError(R"({"command":"hello"})");
    EXPECT_EQ(missing.code, ErrorCode::BadRequest);
    EXPECT_NE(missing.message.find("cmd"), std::string::npos);
    for (const char* line : {R"({"cmd":1})", R"({"cmd":null})", R"({"cmd":["hello"]})",
                             R"({"cmd":{"name":"hello"}})", R"({"cmd":true})"}) {
        const ProtocolError error = parseError(line);
        EXPECT_EQ(error.code, ErrorCode::BadRequest) << line;
        EXPECT_NE(error.message.find("\"cmd\" must be a string"), std::string::npos)
            << error.message;
    }
}

TEST(ProtocolParse, UnknownCommandListsTheKnownOnes)
{
    const ProtocolError error = parseError(R"({"cmd":"fly"})");
    EXPECT_EQ(error.code, ErrorCode::UnknownCommand);
    EXPECT_NE(error.message.find("\"fly\""), std::string::npos);
    for (const std::string& command : knownCommands())
        EXPECT_NE(error.message.find(command), std::string::npos) << command;
    // Names are case-sensitive.
    EXPECT_EQ(parseError(R"({"cmd":"HELLO"})").code, ErrorCode::UnknownCommand);
}

TEST(ProtocolParse, LongNamesAreCutInMessages)
{
    const std::string name(5000, 'x');
    const ProtocolError error = parseError(R"({"cmd":")" + name + "\"}");
    EXPECT_EQ(error.code, ErrorCode::UnknownCommand);
    EXPECT_LT(error.message.size(), 300u);
}

TEST(ProtocolParse, OutOfRangeNumbersAreBadRequest)
{
    for (const char* line :
         {R"({"cmd":"distance","max_age_ms":-1})", R"({"cmd":"distance","max_age_ms":0})",
          R"({"cmd":"distance","max_age_ms":-1e308})",
          R"({"cmd":"subscribe","stream":"depth","max_hz":0})",
          R"({"cmd":"subscribe","stream":"depth","max_hz":-3.5})"}) {
        const ProtocolError error = parseError(line);
        EXPECT_EQ(error.code, ErrorCode::BadRequest) << line;
        EXPECT_NE(error.message.find("> 0"), std::string::npos) << error.message;
    }
}

TEST(ProtocolParse, HugeNumbers)
{
    // Beyond the range of a double: refused by the JSON reader, as a number overflow.
    EXPECT_EQ(parseError(R"({"cmd":"distance","max_age_ms":1e400})").code, ErrorCode::BadJson);
    // Large but finite: a valid (if generous) limit.
    EXPECT_DOUBLE_EQ(
        std::get<DistanceRequest>(parseOk(R"({"cmd":"distance","max_age_ms":1e300})").command)
            .max_age_ms.value_or(0),
        1e300);
    // Integers beyond 64 bits become doubles.
    EXPECT_GT(
        std::get<DistanceRequest>(
            parseOk(R"({"cmd":"distance","max_age_ms":123456789012345678901234567890})").command)
            .max_age_ms.value_or(0),
        1e29);
}

TEST(ProtocolParse, WrongTypesNameTheField)
{
    struct Case {
        const char* line;
        const char* field;
    };
    for (const Case& c :
         {Case{R"({"cmd":"distance","max_age_ms":"500"})", "max_age_ms"},
          Case{R"({"cmd":"distance","max_age_ms":true})", "max_age_ms"},
          Case{R"({"cmd":"subscribe"})", "stream"},
          Case{R"({"cmd":"subscribe","stream":5})", "stream"},
          Case{R"({"cmd":"subscribe","stream":"video"})", "video"},
          Case{R"({"cmd":"subscribe","stream":"depth","max_hz":[5]})", "max_hz"},
          Case{R"({"cmd":"snapshot","items":"depth"})", "items"},
          Case{R"({"cmd":"snapshot","items":["depth",7]})", "items\"[1]"},
          Case{R"({"cmd":"snapshot","items":["depth","mesh"]})", "mesh"},
          Case{R"({"cmd":"subscribe","stream":"raw","with":"depth"})", "with"},
          Case{R"({"cmd":"subscribe","stream":"raw","with":["mesh"]})", "known: depth, cloud"},
          Case{R"({"cmd":"subscribe","stream":"depth","with":["depth"]})", "raw stream only"}}) {
        const ProtocolError error = parseError(c.line);
        EXPECT_EQ(error.code, ErrorCode::BadRequest) << c.line;
        EXPECT_NE(error.message.find(c.field), std::string::npos)
            << c.line << " -> " << error.message;
    }
}

TEST(ProtocolParse, DeepNestingDoesNotCrash)
{
    const std::string deep =
        R"({"cmd":"hello","x":)" + std::string(20000, '[') + std::string(20000, ']') + "}";
    EXPECT_TRUE(std::holds_alternative<HelloRequest>(parseOk(deep).command));
    EXPECT_EQ(parseError(std::string(20000, '[')).code, ErrorCode::BadJson);
    // An id is echoed (copied, written): its depth is bounded.
    const ProtocolError deep_id = parseError(R"({"cmd":"hello","id":)" + std::string(30000, '[') +
                                             std::string(30000, ']') + "}");
    EXPECT_EQ(deep_id.code, ErrorCode::BadRequest);
    EXPECT_FALSE(deep_id.id.has_value());
    EXPECT_EQ(parseOk(R"({"cmd":"hello","id":[[[[1]]]]})").id, Json::parse("[[[[1]]]]"));
}

TEST(ProtocolParse, IdNestingLimitIsSixteenLevels)
{
    const auto nested = [](int levels, const std::string& inner) {
        return std::string(static_cast<std::size_t>(levels), '[') + inner +
               std::string(static_cast<std::size_t>(levels), ']');
    };
    for (const std::string& inner : {std::string(), std::string("1")}) {
        const std::string sixteen = nested(16, inner);
        EXPECT_EQ(parseOk(R"({"cmd":"hello","id":)" + sixteen + "}").id, Json::parse(sixteen))
            << inner;
        const ProtocolError seventeen =
            parseError(R"({"cmd":"hello","id":)" + nested(17, inner) + "}");
        EXPECT_EQ(seventeen.code, ErrorCode::BadRequest) << inner;
        EXPECT_NE(seventeen.message.find("16 levels"), std::string::npos) << seventeen.message;
    }
    EXPECT_EQ(parseError(R"({"cmd":"hello","id":)" + std::string(16, '[') + "{\"a\":[]}" +
                         std::string(16, ']') + "}")
                  .code,
              ErrorCode::BadRequest);
}

TEST(ProtocolParse, NulByteAnywhereIsRefused)
{
    for (const std::string& line :
         {std::string("{\"cmd\":\"hello\"}\0", 17), std::string("{\"cmd\":\"hello\"}\0junk", 21),
          std::string("{\"cmd\":\"hel\0lo\"}", 17), std::string("\0{\"cmd\":\"hello\"}", 17)}) {
        const ProtocolError error = parseError(line);
        EXPECT_EQ(error.code, ErrorCode::BadJson) << line.size();
        EXPECT_NE(error.message.find("NUL"), std::string::npos) << error.message;
    }
}

TEST(ProtocolParse, EveryByteValueAlone)
{
    for (int byte = 0; byte < 256; ++byte) {
        const std::string line(1, static_cast<char>(byte));
        const ParseResult result = parseRequest(line);
        ASSERT_TRUE(std::holds_alternative<ProtocolError>(result)) << byte;
        EXPECT_EQ(std::get<ProtocolError>(result).code, ErrorCode::BadJson) << byte;
    }
}

} // namespace
} // namespace stereod
