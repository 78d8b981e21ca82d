#pragma once
// A setting refused by the code that owns it, named by that code's own field: the matcher
// says "num_disparities", the processor (which holds the matcher's settings as `matcher`)
// says "matcher.num_disparities". config/ turns the field into the key a user wrote and adds
// the file and line it knows; the core knows neither.
//
// Thread contract: a value; any thread. Ownership: owns its strings. Units: none (the
// problem's text names its own).

#include <stdexcept>
#include <string>

namespace stereod {

class SettingsError : public std::invalid_argument {
  public:
    // what() reads "<field>: <problem>".
    SettingsError(std::string field, std::string problem)
        : std::invalid_argument(field + ": " + problem), field_(std::move(field)),
          problem_(std::move(problem))
    {
    }

    const std::string& field() const noexcept { return field_; }
    const std::string& problem() const noexcept { return problem_; }

    // The same refusal named from the settings that hold these as `member`:
    // SettingsError("p2", ...).within("matcher") names "matcher.p2".
    SettingsError within(const std::string& member) const
    {
        return SettingsError(member + "." + field_, problem_);
    }

  private:
    std::string field_;
    std::string problem_;
};

} // namespace stereod
