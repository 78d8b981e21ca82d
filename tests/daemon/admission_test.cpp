// Who may use the live view, as pure rules (daemon/live_view/admission.hpp): the token in
// the URL or the page's cookie, the browser's Origin against the page's own and the
// allowed ones. The server applying them to real requests: live_view_test.cpp.
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "daemon/live_view/admission.hpp"

namespace stereod::live_view {
namespace {

constexpr uint16_t kPort = 8765;
const std::string kToken = "0123456789abcdef0123456789abcdef";

Admission admitOne(const std::string& resource, const std::string& origin,
                   const std::string& cookies, const std::vector<std::string>& allowed = {})
{
    return admit({resource, origin, "127.0.0.1:8765", cookies}, kToken, allowed, kPort);
}

TEST(Admission, QueryAndCookieValues)
{
    EXPECT_EQ(queryValue("/?token=abc", "token"), "abc");
    EXPECT_EQ(queryValue("/x?a=1&token=abc&b=2", "token"), "abc");
    EXPECT_EQ(queryValue("/x?tokens=abc", "token"), "");
    EXPECT_EQ(queryValue("/x?token", "token"), "");
    EXPECT_EQ(queryValue("/x?token=abc#frag", "token"), "abc");
    EXPECT_EQ(queryValue("/x#?token=abc", "token"), "abc"); // a fragment never reaches a server
    EXPECT_EQ(queryValue("/token=abc", "token"), "");
    EXPECT_EQ(cookieValue("a=1; stereod_live_view_8765=abc ;b=2", "stereod_live_view_8765"), "abc");
    EXPECT_EQ(cookieValue("stereod_live_view_87650=abc", "stereod_live_view_8765"), "");
    EXPECT_EQ(cookieValue("", "x"), "");
    EXPECT_EQ(cookieValue(";;=;x", "x"), "");
}

TEST(Admission, TheTokenByUrlOrCookie)
{
    EXPECT_EQ(admitOne("/?token=" + kToken, "", ""), Admission::Allowed);
    EXPECT_EQ(admitOne("/", "", "stereod_live_view_8765=" + kToken), Admission::Allowed);
    EXPECT_EQ(admitOne("/", "", ""), Admission::NoToken);
    EXPECT_EQ(admitOne("/?token=", "", ""), Admission::NoToken);
    EXPECT_EQ(admitOne("/?token=" + kToken + "0", "", ""), Admission::WrongToken);
    EXPECT_EQ(admitOne("/", "", "stereod_live_view_8766=" + kToken), Admission::NoToken);
    // The URL's token decides when both are there (a page reopened after a restart).
    EXPECT_EQ(admitOne("/?token=" + std::string(32, '0'), "", "stereod_live_view_8765=" + kToken),
              Admission::WrongToken);
    EXPECT_TRUE(tokenInUrl({"/?token=" + kToken, "", "", ""}, kToken));
    EXPECT_FALSE(tokenInUrl({"/", "", "", "stereod_live_view_8765=" + kToken}, kToken));
}

TEST(Admission, TheBrowsersOriginMustBeTheLiveViewsOrAllowed)
{
    const std::string t = "/?token=" + kToken;
    EXPECT_EQ(admitOne(t, "http://127.0.0.1:8765", ""), Admission::Allowed);
    EXPECT_EQ(admitOne(t, "HTTP://127.0.0.1:8765", ""), Admission::Allowed);
    EXPECT_EQ(admitOne(t, "http://127.0.0.2:8765", ""), Admission::ForeignOrigin);
    EXPECT_EQ(admitOne(t, "https://127.0.0.1:8765", ""), Admission::ForeignOrigin);
    EXPECT_EQ(admitOne(t, "http://127.0.0.1:8766", ""), Admission::ForeignOrigin);
    EXPECT_EQ(admitOne(t, "null", ""), Admission::ForeignOrigin);
    EXPECT_EQ(admitOne("/", "http://evil.example", ""), Admission::ForeignOrigin);
    const std::vector<std::string> foxglove = {"https://app.foxglove.dev"};
    EXPECT_EQ(admitOne(t, "https://app.foxglove.dev", "", foxglove), Admission::Allowed);
    EXPECT_EQ(admitOne(t, "https://app.foxglove.dev.evil", "", foxglove), Admission::ForeignOrigin);
    EXPECT_EQ(admitOne("/", "https://app.foxglove.dev", "", foxglove), Admission::NoToken);
    EXPECT_EQ(admitOne(t, "http://anything", "", {"*"}), Admission::Allowed);
}

TEST(Admission, TokensAreRandomHexAndComparedWhole)
{
    std::set<std::string> seen;
    for (int i = 0; i < 100; ++i) {
        const std::string token = newToken();
        ASSERT_EQ(token.size(), 32u);
        EXPECT_EQ(token.find_first_not_of("0123456789abcdef"), std::string::npos) << token;
        seen.insert(token);
    }
    EXPECT_EQ(seen.size(), 100u);
    EXPECT_TRUE(sameToken("abc", "abc"));
    EXPECT_FALSE(sameToken("abc", "abd"));
    EXPECT_FALSE(sameToken("abc", "abcd"));
    EXPECT_FALSE(sameToken("", "a"));
    EXPECT_EQ(tokenCookie("t", 8765),
              "stereod_live_view_8765=t; Path=/; HttpOnly; SameSite=Strict");
}

} // namespace
} // namespace stereod::live_view
