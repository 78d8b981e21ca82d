// What every reply has in common: ok, id, error codes, one line of valid JSON; and hello.

#include <string>

#include <gtest/gtest.h>

#include "protocol/reply.hpp"

namespace stereod {
namespace {

TEST(ProtocolReplies, ErrorReplyShape)
{
    std::string line;
    appendJsonLine(line, errorReply(ErrorCode::RequestTooLarge, "too long", Json(7)));
    ASSERT_FALSE(line.empty());
    EXPECT_EQ(line.back(), '\n');
    EXPECT_EQ(line.find('\n'), line.size() - 1);
    const Json reply = Json::parse(line);
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
    EXPECT_EQ(reply["commands"].size(), 9u);
    EXPECT_EQ(reply["commands"].back(), "view");
    EXPECT_EQ(reply["streams"], Json::parse(R"(["readings","depth","raw","zones"])"));
    EXPECT_EQ(
        reply["snapshot_items"],
        Json::parse(R"(["left","disparity","depth","cloud","raw_left","raw_right","confidence",
                       "left_colour","cloud_colour","raw_left_colour","raw_right_colour"])"));
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

} // namespace
} // namespace stereod
