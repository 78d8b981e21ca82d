#include "daemon/log_limiter.hpp"

#include <algorithm>
#include <cstring>

namespace stereod {

LogLimiter::LogLimiter(int64_t interval_ns) noexcept : interval_ns_(interval_ns) {}

LogLimiter::Entry& LogLimiter::entryFor(std::string_view key) noexcept
{
    key = key.substr(0, kMaxKeyBytes);
    Entry* unused = nullptr;
    Entry* oldest = &entries_[0];
    for (Entry& entry : entries_) {
        if (entry.key[0] == '\0') {
            if (unused == nullptr)
                unused = &entry;
            continue;
        }
        if (key == std::string_view(entry.key.data()))
            return entry;
        if (entry.last_logged_ns < oldest->last_logged_ns)
            oldest = &entry;
    }
    Entry& fresh = unused != nullptr ? *unused : *oldest;
    fresh = Entry{};
    std::memcpy(fresh.key.data(), key.data(), key.size());
    fresh.key[key.size()] = '\0';
    return fresh;
}

LogLimiter::Decision LogLimiter::admit(std::string_view key, int64_t now_ns,
                                       spdlog::level::level_enum level) noexcept
{
    Entry& entry = entryFor(key.empty() ? std::string_view("-") : key);
    entry.level = level;
    const bool first = entry.last_logged_ns == 0 && entry.suppressed == 0;
    if (!first && now_ns - entry.last_logged_ns < interval_ns_) {
        ++entry.suppressed;
        return {};
    }
    Decision decision;
    decision.log = true;
    decision.suppressed = entry.suppressed;
    entry.suppressed = 0;
    // 0 marks "never logged"; a clock reading of exactly 0 is taken as 1 ns.
    entry.last_logged_ns = std::max<int64_t>(now_ns, 1);
    return decision;
}

void LogLimiter::flush(int64_t now_ns)
{
    for (Entry& entry : entries_) {
        if (entry.key[0] == '\0' || entry.suppressed == 0 ||
            now_ns - entry.last_logged_ns < interval_ns_)
            continue;
        spdlog::log(entry.level, "{}: repeated {} times in the last {:.1f} s", entry.key.data(),
                    entry.suppressed, static_cast<double>(now_ns - entry.last_logged_ns) / 1e9);
        entry.suppressed = 0;
        entry.last_logged_ns = std::max<int64_t>(now_ns, 1);
    }
}

} // namespace stereod
