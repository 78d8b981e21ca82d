#pragma once
// One table of an enum's names, from which naming, parsing and listing all come: a value
// added to the enum is named in one place, and every switch that named it is gone.
// Entries are listed in the order their names are shown to users ("known: a, b, c").
//
//   inline constexpr NameTable<StreamKind, 2> kStreamNames{{{
//       {StreamKind::Readings, "readings"}, {StreamKind::Depth, "depth"}}}};
//   static_assert(kStreamNames.wellFormed());
//
// Thread contract: immutable, constexpr; any thread.

#include <array>
#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace stereod {

template <class Enum, std::size_t N> struct NameTable {
    struct Entry {
        Enum value;
        const char* name;
    };
    std::array<Entry, N> entries;

    // The value's name; `fallback` for a value the table lacks (an enum out of range).
    constexpr const char* name(Enum value, const char* fallback = "?") const noexcept
    {
        for (const Entry& entry : entries)
            if (entry.value == value)
                return entry.name;
        return fallback;
    }
    // The value of that name; none when no entry has it.
    constexpr std::optional<Enum> parse(std::string_view name) const noexcept
    {
        for (const Entry& entry : entries)
            if (name == entry.name)
                return entry.value;
        return std::nullopt;
    }
    // Every entry named, and no name or value twice: each table is checked with
    // static_assert(table.wellFormed()), so that a table longer than its entries (the
    // rest value-initialised, unnamed) does not compile.
    constexpr bool wellFormed() const noexcept
    {
        for (std::size_t i = 0; i < N; ++i) {
            if (entries[i].name == nullptr)
                return false;
            for (std::size_t j = 0; j < i; ++j)
                if (entries[j].value == entries[i].value ||
                    std::string_view(entries[j].name) == entries[i].name)
                    return false;
        }
        return true;
    }
    // Every name, in the table's order.
    std::vector<std::string> names() const
    {
        std::vector<std::string> all;
        all.reserve(N);
        for (const Entry& entry : entries)
            all.emplace_back(entry.name);
        return all;
    }
};

} // namespace stereod
