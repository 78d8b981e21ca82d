#include "config/name_suggestions.hpp"

#include <algorithm>
#include <cctype>

#include "config/yaml_scalars.hpp"

namespace stereod::config_detail {

// ---------------------------------------------------------------------------------------
// "Did you mean": the closest known name, by edit distance with transpositions.

std::string normalizedName(std::string_view name)
{
    std::string out = lowercase(name);
    std::replace(out.begin(), out.end(), '-', '_');
    std::replace(out.begin(), out.end(), ' ', '_');
    return out;
}

namespace {

size_t editDistance(std::string_view a, std::string_view b)
{
    std::vector<std::vector<size_t>> d(a.size() + 1, std::vector<size_t>(b.size() + 1));
    for (size_t i = 0; i <= a.size(); ++i) {
        d[i][0] = i;
    }
    for (size_t j = 0; j <= b.size(); ++j) {
        d[0][j] = j;
    }
    for (size_t i = 1; i <= a.size(); ++i) {
        for (size_t j = 1; j <= b.size(); ++j) {
            const size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
            d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) {
                d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
            }
        }
    }
    return d[a.size()][b.size()];
}

} // namespace

std::optional<std::string> closestName(std::string_view given,
                                       const std::vector<std::string>& candidates)
{
    // Long names tolerate more typos; a short one must be nearly right to be suggested.
    const std::string wanted = normalizedName(given);
    if (wanted.size() > 64) {
        return std::nullopt;
    }
    const size_t tolerance = wanted.size() <= 3 ? 1 : wanted.size() <= 8 ? 2 : 3;
    std::optional<std::string> best;
    size_t best_distance = tolerance + 1;
    for (const auto& candidate : candidates) {
        const size_t distance = editDistance(wanted, normalizedName(candidate));
        if (distance < best_distance) {
            best_distance = distance;
            best = candidate;
        }
    }
    return best;
}

std::string listNames(const std::vector<std::string>& names)
{
    std::string out;
    for (size_t i = 0; i < names.size(); ++i) {
        out += i == 0 ? "" : i + 1 == names.size() ? " or " : ", ";
        out += names[i];
    }
    return out;
}

// What a message expects of a name: "a, b or c", and the closest to what was given.
std::string expectedOneOf(const std::vector<std::string>& known, std::string_view given)
{
    std::string expected = listNames(known);
    if (auto suggestion = closestName(given, known)) {
        expected += "; did you mean " + *suggestion + "?";
    }
    return expected;
}

} // namespace stereod::config_detail
