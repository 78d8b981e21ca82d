// The Foxglove WebSocket protocol's messages, without sockets.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "daemon/live_view/foxglove_protocol.hpp"
#include "daemon/live_view/live_view.hpp"
#include "protocol/reading_json.hpp"

namespace stereod::live_view {
namespace {

using nlohmann::json;

TEST(FoxgloveProtocol, SubscribeAndUnsubscribeAreRead)
{
    const ClientRequest sub = parseClientMessage(
        R"({"op":"subscribe","subscriptions":[{"id":0,"channelId":3},{"id":7,"channelId":1}]})");
    ASSERT_EQ(sub.kind, ClientRequest::Kind::Subscribe);
    ASSERT_EQ(sub.subscriptions.size(), 2u);
    EXPECT_EQ(sub.subscriptions[1], std::make_pair(7u, 1u));
    const ClientRequest unsub =
        parseClientMessage(R"({"op":"unsubscribe","subscriptionIds":[0,7]})");
    ASSERT_EQ(unsub.kind, ClientRequest::Kind::Unsubscribe);
    EXPECT_EQ(unsub.unsubscriptions, (std::vector<uint32_t>{0, 7}));
}

TEST(FoxgloveProtocol, MalformedRequestsSayWhatIsWrong)
{
    for (const char* text :
         {"", "[]", "{", R"({"op":5})", R"({"op":"subscribe"})",
          R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]})",
          R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":4294967296}]})",
          R"({"op":"subscribe","subscriptions":[{"id":1.5,"channelId":1}]})",
          R"({"op":"unsubscribe","subscriptionIds":["a"]})"}) {
        const ClientRequest request = parseClientMessage(text);
        EXPECT_EQ(request.kind, ClientRequest::Kind::Invalid) << text;
        EXPECT_FALSE(request.problem.empty()) << text;
    }
    const ClientRequest advertise = parseClientMessage(R"({"op":"advertise","channels":[]})");
    EXPECT_EQ(advertise.kind, ClientRequest::Kind::Ignored);
    EXPECT_NE(advertise.problem.find("advertise"), std::string::npos);
}

// Whether `value` is of the JSON schema type `type` (a name, or a list of names).
bool ofSchemaType(const json& value, const json& type)
{
    if (type.is_array()) {
        for (const json& one : type)
            if (ofSchemaType(value, one))
                return true;
        return false;
    }
    const std::string name = type.get<std::string>();
    return (name == "boolean" && value.is_boolean()) ||
           (name == "integer" && value.is_number_integer()) ||
           (name == "number" && value.is_number()) || (name == "string" && value.is_string()) ||
           (name == "object" && value.is_object()) || (name == "null" && value.is_null());
}

// /stereo/nearest's schema declares what a reading object carries, with its types: a
// valid one flagged calibration_suspect, one nearer than the range, one without a
// reading (reason an object {code, message}), and frame always.
TEST(FoxgloveProtocol, TheReadingSchemaDeclaresEveryFieldOfAReading)
{
    const json schema = json::parse(channelSpecs()[kNearest - 1].schema);
    ASSERT_EQ(channelSpecs()[kNearest - 1].topic, "/stereo/nearest");
    const json& properties = schema["properties"];
    ReadingReport suspect;
    suspect.reading.valid = true;
    suspect.reading.reason = NoReadingReason::None;
    suspect.reading.distance_m = 1.5;
    suspect.reading.stamp_ns = 1000;
    suspect.reading.frame = 7;
    suspect.reading.calibration_suspect = true;
    suspect.reading.calibration_row_offset_px = 1.2;
    suspect.realtime_offset_ns = 1'764'000'000'000'000'000;
    ReadingReport nearer;
    nearer.reading.reason = NoReadingReason::NearerThanRange;
    nearer.reading.nearer_than_m = 0.4;
    ReadingReport none;
    none.reading.reason = NoReadingReason::TooFewValidPixels;
    std::size_t fields = 0;
    for (const ReadingReport* report : {&suspect, &nearer, &none}) {
        const json reading = readingToJson(*report, 5000);
        for (const auto& [key, value] : reading.items()) {
            ASSERT_TRUE(properties.contains(key)) << key << " is not in the schema";
            EXPECT_TRUE(ofSchemaType(value, properties[key]["type"]))
                << key << ": " << value << " is not " << properties[key]["type"];
            ++fields;
        }
        for (const json& key : schema["required"])
            EXPECT_TRUE(reading.contains(key.get<std::string>())) << key;
    }
    EXPECT_GE(fields, 30u);
    EXPECT_EQ(properties["reason"]["type"], "object");
    EXPECT_TRUE(properties["reason"]["properties"].contains("code"));
    EXPECT_TRUE(properties["reason"]["properties"].contains("message"));
}

TEST(FoxgloveProtocol, MessageDataFrameIsOpcodeIdTimeThenPayload)
{
    std::string frame;
    appendMessageData(0x01020304, 0x1122334455667788ull, "abc", frame);
    ASSERT_EQ(frame.size(), 1u + 4 + 8 + 3);
    EXPECT_EQ(frame[0], 0x01);
    EXPECT_EQ(static_cast<uint8_t>(frame[1]), 0x04); // little-endian
    EXPECT_EQ(static_cast<uint8_t>(frame[4]), 0x01);
    EXPECT_EQ(static_cast<uint8_t>(frame[5]), 0x88);
    EXPECT_EQ(static_cast<uint8_t>(frame[12]), 0x11);
    EXPECT_EQ(frame.substr(13), "abc");
    setSubscriptionId(frame, 0x0a0b0c0d);
    EXPECT_EQ(static_cast<uint8_t>(frame[1]), 0x0d);
    EXPECT_EQ(static_cast<uint8_t>(frame[4]), 0x0a);
    EXPECT_EQ(static_cast<uint8_t>(frame[5]), 0x88); // the rest untouched
    EXPECT_EQ(frame.substr(13), "abc");
}

TEST(FoxgloveProtocol, AdvertiseListsEveryChannelWithItsSchema)
{
    const json advertise = json::parse(advertiseJson(channelSpecs()));
    EXPECT_EQ(advertise["op"], "advertise");
    ASSERT_EQ(advertise["channels"].size(), 10u);
    for (const json& channel : advertise["channels"]) {
        EXPECT_FALSE(channel["schema"].get<std::string>().empty()) << channel["topic"];
        const bool cdr = channel["encoding"] == "cdr";
        EXPECT_EQ(channel["schemaEncoding"], cdr ? "ros2msg" : "jsonschema");
        if (!cdr) {
            EXPECT_TRUE(json::accept(channel["schema"].get<std::string>())) << channel["topic"];
        }
    }
    const json info = json::parse(serverInfoJson("stereod", "42"));
    EXPECT_EQ(info["op"], "serverInfo");
    EXPECT_TRUE(info["capabilities"].empty());
}

} // namespace
} // namespace stereod::live_view
