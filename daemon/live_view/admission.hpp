#pragma once
// Who may use the live view (docs/live-view.md, "Who may watch"): the rules the WebSocket
// and HTTP server applies to every request before serving it, as pure functions, so that
// they are unit-tested apart from any socket.
//
//  - The token: every request carries the live view's token, in its URL (`?token=...`, as
//    `stereoctl view` prints it, and as Foxglove sends it) or in the cookie that a page
//    loaded with the token gets (so the page's own requests, and its WebSocket, need not
//    repeat it). The token is made at start-up from the kernel's random source and given
//    only over the service's Unix socket, so only those who may use the socket can watch.
//  - The Origin: a browser names the page that opened a request; a request from a page
//    other than the live view's own (http://HOST:PORT as the browser reached it) or one of
//    live_view.allowed_origins is refused, token or not. Programs send no Origin.
//
// Reentrant: no state; newToken() reads the kernel's random source.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace stereod::live_view {

// What one request shows of itself: its target ("/path?query"), and its Origin, Host and
// Cookie headers ("" when absent).
struct RequestView {
    std::string_view resource;
    std::string_view origin;
    std::string_view host;
    std::string_view cookies;
};

enum class Admission {
    Allowed,
    ForeignOrigin, // a page the live view does not know opened it
    NoToken,       // neither the URL nor the cookie carries a token
    WrongToken,    // one does, and it is not this service's
};

// Why a request was refused, for the refusal's body and the log.
const char* admissionText(Admission admission) noexcept;

// The rules above. `allowed_origins` as in live_view.allowed_origins (exact values such as
// "https://app.foxglove.dev"; "*" admits any page).
Admission admit(const RequestView& request, std::string_view token,
                const std::vector<std::string>& allowed_origins, uint16_t port);

// True when the token came in the request's URL (the reply then sets the cookie).
bool tokenInUrl(const RequestView& request, std::string_view token);

// The cookie carrying the token of the live view on `port` (cookies do not tell ports
// apart: two services on one host keep theirs under two names).
std::string tokenCookieName(uint16_t port);

// The Set-Cookie value that hands a page the token: HttpOnly (the page's scripts never
// see it), SameSite=Strict (no other site's page sends it).
std::string tokenCookie(std::string_view token, uint16_t port);

// `name`'s value in the query of `resource`, or "" when absent.
std::string_view queryValue(std::string_view resource, std::string_view name);

// `name`'s value in a Cookie header ("a=1; b=2"), or "" when absent.
std::string_view cookieValue(std::string_view cookies, std::string_view name);

// Equality in time independent of where the two differ.
bool sameToken(std::string_view a, std::string_view b) noexcept;

// 128 random bits as 32 lowercase hex digits. Throws std::system_error when the kernel's
// random source cannot be read.
std::string newToken();

} // namespace stereod::live_view
