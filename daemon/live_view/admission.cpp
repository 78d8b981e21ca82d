#include "daemon/live_view/admission.hpp"

#include <algorithm>
#include <cerrno>
#include <system_error>

#include <sys/random.h>

namespace stereod::live_view {

namespace {

bool equalNoCase(std::string_view a, std::string_view b)
{
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
               const auto lower = [](char c) { return c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c; };
               return lower(x) == lower(y);
           });
}

std::string_view trim(std::string_view s)
{
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t'))
        s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t'))
        s.remove_suffix(1);
    return s;
}

bool originAllowed(const RequestView& request, const std::vector<std::string>& allowed_origins)
{
    if (request.origin.empty())
        return true; // not a browser: a program, which no web page can drive
    if (!request.host.empty() && equalNoCase(request.origin.substr(0, 7), "http://") &&
        equalNoCase(request.origin.substr(7), request.host))
        return true; // the live view's own page
    return std::any_of(allowed_origins.begin(), allowed_origins.end(),
                       [&](const std::string& o) { return o == "*" || o == request.origin; });
}

} // namespace

const char* admissionText(Admission admission) noexcept
{
    switch (admission) {
    case Admission::Allowed:
        return "allowed";
    case Admission::ForeignOrigin:
        return "a page of another origin than the live view's own or "
               "live_view.allowed_origins opened it";
    case Admission::NoToken:
        return "the request carries no token: open the address `stereoctl view` prints "
               "(with its ?token=)";
    case Admission::WrongToken:
        return "the request's token is not this service's (a restart makes a new one): "
               "open the address `stereoctl view` prints";
    }
    return "refused";
}

std::string_view queryValue(std::string_view resource, std::string_view name)
{
    const std::size_t question = resource.find('?');
    if (question == std::string_view::npos)
        return {};
    std::string_view query = resource.substr(question + 1);
    query = query.substr(0, query.find('#'));
    while (!query.empty()) {
        const std::size_t amp = query.find('&');
        const std::string_view pair = query.substr(0, amp);
        const std::size_t equals = pair.find('=');
        if (pair.substr(0, equals) == name)
            return equals == std::string_view::npos ? std::string_view() : pair.substr(equals + 1);
        if (amp == std::string_view::npos)
            break;
        query.remove_prefix(amp + 1);
    }
    return {};
}

std::string_view cookieValue(std::string_view cookies, std::string_view name)
{
    while (!cookies.empty()) {
        const std::size_t semicolon = cookies.find(';');
        const std::string_view pair = trim(cookies.substr(0, semicolon));
        const std::size_t equals = pair.find('=');
        if (equals != std::string_view::npos && trim(pair.substr(0, equals)) == name)
            return trim(pair.substr(equals + 1));
        if (semicolon == std::string_view::npos)
            break;
        cookies.remove_prefix(semicolon + 1);
    }
    return {};
}

bool sameToken(std::string_view a, std::string_view b) noexcept
{
    if (a.size() != b.size())
        return false;
    unsigned char difference = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
        difference |= static_cast<unsigned char>(a[i] ^ b[i]);
    return difference == 0;
}

std::string tokenCookieName(uint16_t port)
{
    return "stereod_live_view_" + std::to_string(port);
}

std::string tokenCookie(std::string_view token, uint16_t port)
{
    return tokenCookieName(port) + "=" + std::string(token) + "; Path=/; HttpOnly; SameSite=Strict";
}

bool tokenInUrl(const RequestView& request, std::string_view token)
{
    return sameToken(queryValue(request.resource, "token"), token);
}

Admission admit(const RequestView& request, std::string_view token,
                const std::vector<std::string>& allowed_origins, uint16_t port)
{
    if (!originAllowed(request, allowed_origins))
        return Admission::ForeignOrigin;
    std::string_view offered = queryValue(request.resource, "token");
    if (offered.empty())
        offered = cookieValue(request.cookies, tokenCookieName(port));
    if (offered.empty())
        return Admission::NoToken;
    return sameToken(offered, token) ? Admission::Allowed : Admission::WrongToken;
}

std::string newToken()
{
    unsigned char bytes[16];
    std::size_t got = 0;
    while (got < sizeof bytes) {
        const ssize_t n = ::getrandom(bytes + got, sizeof bytes - got, 0);
        if (n < 0) {
            if (errno == EINTR)
                continue;
            throw std::system_error(errno, std::generic_category(),
                                    "live view: cannot read the kernel's random source");
        }
        got += static_cast<std::size_t>(n);
    }
    static constexpr char kHex[] = "0123456789abcdef";
    std::string token;
    for (const unsigned char b : bytes) {
        token.push_back(kHex[b >> 4]);
        token.push_back(kHex[b & 0x0f]);
    }
    return token;
}

} // namespace stereod::live_view
