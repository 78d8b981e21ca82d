// The protocol without sockets: the request parser on good and bad input, and the reading
// object and event lines the service writes (docs/protocol.md).

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "daemon/json_writer.hpp"
#include "daemon/protocol.hpp"

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

// The JSON text must parse (strictly, as UTF-8) whatever went into it.
Json parseStrict(const std::string& text)
{
    return Json::parse(text);
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
    EXPECT_NO_THROW(parseStrict(reply)) << reply;
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

TEST(ProtocolReplies, ErrorReplyShape)
{
    std::string line;
    appendJsonLine(line, errorReply(ErrorCode::RequestTooLarge, "too long", Json(7)));
    ASSERT_FALSE(line.empty());
    EXPECT_EQ(line.back(), '\n');
    EXPECT_EQ(line.find('\n'), line.size() - 1);
    const Json reply = parseStrict(line);
    EXPECT_EQ(reply["ok"], false);
    EXPECT_EQ(reply["id"], 7);
    EXPECT_EQ(reply["error"]["code"], "request_too_large");
    EXPECT_EQ(reply["error"]["message"], "too long");
}

TEST(ProtocolReplies, HelloListsCommandsStreamsAndItems)
{
    const Json reply = helloReply(std::nullopt);
    EXPECT_EQ(reply["ok"], true);
    EXPECT_FALSE(reply.contains("id"));
    EXPECT_EQ(reply["service"], "stereod");
    EXPECT_EQ(reply["protocol"], kProtocolVersion);
    EXPECT_EQ(reply["commands"].size(), 8u);
    EXPECT_EQ(reply["streams"], Json::parse(R"(["readings","depth","raw","zones"])"));
    EXPECT_EQ(
        reply["snapshot_items"],
        Json::parse(R"(["left","disparity","depth","cloud","raw_left","raw_right","confidence"])"));
}

TEST(ProtocolReplies, ErrorCodeNamesAreTheDocumentedOnes)
{
    EXPECT_STREQ(errorCodeName(ErrorCode::BadJson), "bad_json");
    EXPECT_STREQ(errorCodeName(ErrorCode::BadRequest), "bad_request");
    EXPECT_STREQ(errorCodeName(ErrorCode::UnknownCommand), "unknown_command");
    EXPECT_STREQ(errorCodeName(ErrorCode::RequestTooLarge), "request_too_large");
    EXPECT_STREQ(errorCodeName(ErrorCode::TooManyClients), "too_many_clients");
    EXPECT_STREQ(errorCodeName(ErrorCode::NotAvailable), "not_available");
    EXPECT_STREQ(errorCodeName(ErrorCode::InvalidConfig), "invalid_config");
    EXPECT_STREQ(errorCodeName(ErrorCode::Internal), "internal");
    EXPECT_STREQ(errorCodeName(ErrorCode::NotAllowed), "not_allowed");
    EXPECT_STREQ(errorCodeName(ErrorCode::IdleTimeout), "idle_timeout");
}

Reading validReading()
{
    Reading reading;
    reading.valid = true;
    reading.reason = NoReadingReason::None;
    reading.distance_m = 1.41249;
    reading.stamp_ns = 81'263'511'234;
    reading.frame = 118;
    reading.valid_fraction = 0.83;
    reading.in_range_fraction = 0.8;
    reading.min_valid_fraction = 0.1;
    reading.region_pixels = 355680;
    return reading;
}

TEST(ProtocolReading, ValidReadingHasEveryField)
{
    ReadingReport report;
    report.reading = validReading();
    const int64_t now_ns = report.reading.stamp_ns + 37'200'000;
    const Json reading = readingToJson(report, now_ns);
    EXPECT_EQ(reading["valid"], true);
    EXPECT_NEAR(reading["distance_m"].get<double>(), 1.4125, 1e-9);
    EXPECT_EQ(reading["stamp_ns"], 81263511234);
    EXPECT_NEAR(reading["age_ms"].get<double>(), 37.2, 1e-9);
    EXPECT_EQ(reading["frame"], 118);
    EXPECT_NEAR(reading["valid_fraction"].get<double>(), 0.83, 1e-12);
    EXPECT_NEAR(reading["in_range_fraction"].get<double>(), 0.8, 1e-12);
    EXPECT_EQ(reading["region_pixels"], 355680);
    EXPECT_FALSE(reading.contains("reason"));
}

TEST(ProtocolReading, RefusalCarriesReasonWithNumbers)
{
    ReadingReport report;
    report.reading = validReading();
    report.reading.valid = false;
    report.reading.reason = NoReadingReason::TooFewValidPixels;
    report.reading.valid_fraction = 0.02;
    report.reading.in_range_fraction = 0.0;
    const Json reading = readingToJson(report, report.reading.stamp_ns);
    EXPECT_EQ(reading["valid"], false);
    EXPECT_TRUE(reading["distance_m"].is_null());
    EXPECT_EQ(reading["reason"]["code"], "too_few_valid_pixels");
    EXPECT_EQ(reading["reason"]["message"],
              "too few valid pixels in the region: 2.0 % valid, 10.0 % needed");

    report.reading.reason = NoReadingReason::NothingInRange;
    report.reading.valid_fraction = 0.83;
    report.reading.in_range_fraction = 0.0001;
    report.reading.region_pixels = 200000;
    report.reading.min_pixels = 50;
    EXPECT_EQ(readingToJson(report, 0)["reason"]["message"],
              "nothing within the depth range in the region: 20 pixels in range, 50 needed "
              "(83.0 % valid, 0.0 % in range)");
}

TEST(ProtocolReading, GivenMessageWinsAndIsEscaped)
{
    ReadingReport report;
    report.reading = validReading();
    report.reading.valid = false;
    report.reading.reason = NoReadingReason::BadFrame;
    const std::string message = "cannot decode \"left.png\":\n\tbad\x01 byte \xc3 here";
    report.message = message;
    std::string text;
    appendReadingJson(text, report, report.reading.stamp_ns);
    const Json reading = parseStrict(text);
    EXPECT_EQ(reading["reason"]["code"], "bad_frame");
    const std::string got = reading["reason"]["message"];
    EXPECT_EQ(got.substr(0, 28), "cannot decode \"left.png\":\n\tb");
    EXPECT_NE(got.find("\x01"), std::string::npos);
    EXPECT_NE(got.find("\xEF\xBF\xBD"), std::string::npos); // the lone 0xC3 replaced
}

TEST(ProtocolReading, NoFrameYetHasNoStampNorAge)
{
    ReadingReport report;
    report.reading.reason = NoReadingReason::NoFrameYet;
    report.has_frame = false;
    const Json reading = readingToJson(report, 123);
    EXPECT_EQ(reading["valid"], false);
    EXPECT_FALSE(reading.contains("stamp_ns"));
    EXPECT_FALSE(reading.contains("age_ms"));
    EXPECT_EQ(reading["reason"]["code"], "no_frame_yet");

    // A source that failed before its first pair: source_down, still without a stamp.
    report.reading.reason = NoReadingReason::SourceDown;
    report.message = "frame source down: the replay source is failed";
    const Json down = readingToJson(report, 123);
    EXPECT_FALSE(down.contains("stamp_ns"));
    EXPECT_EQ(down["reason"]["code"], "source_down");
    EXPECT_EQ(down["reason"]["message"], "frame source down: the replay source is failed");
}

TEST(ProtocolReading, InconsistentValidFlagIsNeverANumber)
{
    ReadingReport report;
    report.reading = validReading();
    report.reading.reason = NoReadingReason::NothingInRange; // valid stays true
    const Json reading = readingToJson(report, report.reading.stamp_ns);
    EXPECT_EQ(reading["valid"], false);
    EXPECT_TRUE(reading["distance_m"].is_null());
}

TEST(ProtocolEvents, ReadingEventIsOneLine)
{
    ReadingReport report;
    report.reading = validReading();
    std::string line;
    appendReadingEvent(line, report, report.reading.stamp_ns, 0);
    EXPECT_EQ(line.find('\n'), line.size() - 1);
    const Json event = parseStrict(line);
    EXPECT_EQ(event["event"], "reading");
    EXPECT_FALSE(event.contains("skipped"));
    EXPECT_EQ(event["reading"]["frame"], 118);

    line.clear();
    appendReadingEvent(line, report, report.reading.stamp_ns, 3);
    EXPECT_EQ(parseStrict(line)["skipped"], 3);
}

TEST(ProtocolEvents, DepthEventHeaderGivesThePayloadSize)
{
    ReadingReport report;
    report.reading = validReading();
    DepthEventHeader header;
    header.frame = 118;
    header.stamp_ns = report.reading.stamp_ns;
    header.width = 1282;
    header.height = 1110;
    header.bytes = 1282u * 1110u * 2u;
    std::string line;
    appendDepthEventHeader(line, header, report, report.reading.stamp_ns, 2);
    const Json event = parseStrict(line);
    EXPECT_EQ(event["event"], "depth");
    EXPECT_EQ(event["format"], "u16_mm");
    EXPECT_EQ(event["width"], 1282);
    EXPECT_EQ(event["height"], 1110);
    EXPECT_EQ(event["bytes"], 2846040);
    EXPECT_EQ(event["skipped"], 2);
    EXPECT_EQ(event["reading"]["valid"], true);
}

TEST(ProtocolEvents, RawEventHeaderFollowsTheContract)
{
    RawEventHeader header;
    header.frame = 42;
    header.left_stamp_ns = 81263511234;
    header.right_stamp_ns = 81263512001;
    header.width = 640;
    header.height = 480;
    std::string out;
    appendRawEventHeader(out, header, 3);
    ASSERT_EQ(out.back(), '\n');
    EXPECT_EQ(out.find('\n'), out.size() - 1);
    Json event = parseStrict(out);
    EXPECT_EQ(event["event"], "raw");
    EXPECT_EQ(event["frame"], 42);
    EXPECT_EQ(event["left_stamp_ns"], 81263511234);
    EXPECT_EQ(event["right_stamp_ns"], 81263512001);
    EXPECT_EQ(event["skipped"], 3);
    ASSERT_EQ(event["payloads"].size(), 2u);
    EXPECT_EQ(event["payloads"][0],
              Json::parse(R"({"name":"raw_left","format":"u8_gray","width":640,"height":480,)"
                          R"("bytes":307200,"stamp_ns":81263511234})"));
    EXPECT_EQ(event["payloads"][1]["name"], "raw_right");
    EXPECT_EQ(event["payloads"][1]["stamp_ns"], 81263512001);
    EXPECT_EQ(event["payloads"][1]["bytes"], 307200);
    EXPECT_FALSE(event.contains("depth_valid"));

    // With the pair's depth and cloud: their descriptors after the two frames.
    header.depth_valid = true;
    header.depth_width = 620;
    header.depth_height = 470;
    header.cloud_points = 1000;
    out.clear();
    appendRawEventHeader(out, header, 0, true, true);
    event = parseStrict(out);
    EXPECT_EQ(event["depth_valid"], true);
    ASSERT_EQ(event["payloads"].size(), 4u);
    EXPECT_EQ(event["payloads"][2],
              Json::parse(R"({"name":"depth","format":"f32_m","width":620,"height":470,)"
                          R"("bytes":1165600})"));
    EXPECT_EQ(event["payloads"][3],
              Json::parse(R"({"name":"cloud","format":"f32_xyzi","points":1000,"bytes":16000})"));
}

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
    EXPECT_NO_THROW(parseStrict(out));
    EXPECT_DOUBLE_EQ(roundTo(37.20000001, 3), 37.2);
    EXPECT_DOUBLE_EQ(roundTo(1e300, 3), 1e300);
}

} // namespace
} // namespace stereod
