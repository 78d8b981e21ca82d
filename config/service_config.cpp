#include "config/service_config.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <sstream>

#include <arpa/inet.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include "base/system_error.hpp"
#include "config/config_checks.hpp"
#include "config/key_table.hpp"
#include "pipeline/census_sgm_matcher.hpp"
#include "ros2/topic_names.hpp"

namespace stereod {

namespace fs = std::filesystem;
using namespace config_detail;

std::string leftCameraInfoTopic(const Ros2SourceConfig& ros2)
{
    return ros2.left_info_topic.value_or(ros2::cameraInfoTopicBeside(ros2.left_topic));
}

std::string rightCameraInfoTopic(const Ros2SourceConfig& ros2)
{
    return ros2.right_info_topic.value_or(ros2::cameraInfoTopicBeside(ros2.right_topic));
}

namespace {

// ---------------------------------------------------------------------------------------
// Loading

std::string absolutePath(const std::string& path)
{
    std::error_code error;
    const fs::path absolute = fs::absolute(path, error);
    return error ? path : absolute.lexically_normal().string();
}

// Applies the overrides and notes which option set which key.
void overrideKeys(ServiceConfig& config, const ConfigOverrides& overrides, KeyLocations& locations)
{
    const auto apply = [&](const std::string& value, std::string& field, const std::string& key,
                           const char* option, bool is_path) {
        if (value.empty()) {
            return;
        }
        field = is_path ? absolutePath(value) : value;
        locations.lines.erase(key);
        locations.unreadable.erase(key);
        locations.overridden[key] = option;
    };
    apply(overrides.replay_path, config.source.replay.path, "source.replay.path", "--replay", true);
    if (!overrides.replay_path.empty()) {
        // --replay replaces the configured source, cameras included.
        config.source.kind = SourceKind::Replay;
        locations.lines.erase("source.type");
        locations.overridden["source.type"] = "--replay";
    }
    apply(overrides.calibration_path, config.calibration_path, "calibration", "--calib", true);
    apply(overrides.socket_path, config.socket.path, "socket.path", "--socket", true);
    apply(overrides.log_level, config.log_level, "log_level", "--log-level", false);
    apply(overrides.live_view, config.live_view.listen, "live_view.listen", "--live-view", false);
}

// Notes where the second document of a stream starts, and ignores everything else.
class SecondDocumentFinder final : public YAML::EventHandler {
  public:
    void OnDocumentStart(const YAML::Mark& mark) override
    {
        if (++documents_ == 2) {
            second_ = mark;
        }
    }
    void OnDocumentEnd() override {}
    void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
    void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
    void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  const std::string&) override
    {
    }
    void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                         YAML::EmitterStyle::value) override
    {
    }
    void OnSequenceEnd() override {}
    void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                    YAML::EmitterStyle::value) override
    {
    }
    void OnMapEnd() override {}

    std::optional<YAML::Mark> second() const
    {
        return documents_ >= 2 ? std::optional<YAML::Mark>(second_) : std::nullopt;
    }

  private:
    int documents_ = 0;
    YAML::Mark second_ = YAML::Mark::null_mark();
};

// Where a second document starts, if the text has one. yaml-cpp 0.7's LoadAll() never
// returns on some malformed input (found by fuzzing: its parser keeps producing
// documents), so the first document is loaded with Load() and a second one is only
// looked for, with at most two steps of the parser.
std::optional<YAML::Mark> secondDocumentStart(const std::string& text)
{
    std::istringstream stream(text);
    YAML::Parser parser(stream);
    SecondDocumentFinder finder;
    for (int document = 0; document < 2 && parser.HandleNextDocument(finder); ++document) {
    }
    return finder.second();
}

ServiceConfig parseDocument(const std::string& text, const std::string& origin,
                            const ReadContext& context, const ConfigOverrides& overrides)
{
    ServiceConfig config = defaultConfig();
    config.origin = origin;
    KeyLocations locations;
    std::vector<Problem> problems;
    try {
        readDocument(YAML::Load(text), origin, context, config, locations, problems);
        if (const auto mark = secondDocumentStart(text)) {
            const int line = mark->is_null() ? 0 : mark->line + 1;
            problems.push_back(Problem{line, "",
                                       origin + (line > 0 ? ":" + std::to_string(line) : "") +
                                           ": a second YAML document (expected one; "
                                           "remove the \"---\")"});
        }
    } catch (const YAML::Exception& error) {
        // Syntax errors (ParserException) and anything else yaml-cpp refuses.
        std::string message = origin;
        if (!error.mark.is_null()) {
            message += ":" + std::to_string(error.mark.line + 1);
        }
        message += ": YAML syntax error";
        if (!error.mark.is_null()) {
            message += " at column " + std::to_string(error.mark.column + 1);
        }
        problems.push_back(Problem{0, "", message + ": " + error.msg});
        throw ConfigError(inLineOrder(std::move(problems)));
    }
    overrideKeys(config, overrides, locations);
    auto value_problems = checkValues(config, locations);
    problems.insert(problems.end(), std::make_move_iterator(value_problems.begin()),
                    std::make_move_iterator(value_problems.end()));
    if (!problems.empty()) {
        throw ConfigError(inLineOrder(std::move(problems)));
    }
    return config;
}

std::string readConfigFile(const std::string& path)
{
    // A configuration is a few kilobytes; a large file is the wrong file.
    constexpr long kMaxBytes = 1 << 20;
    std::error_code error;
    if (fs::is_directory(path, error)) {
        throw ConfigError({path + ": cannot read the configuration: is a directory"});
    }
    std::FILE* file = std::fopen(path.c_str(), "rb");
    if (file == nullptr) {
        throw ConfigError({path + ": cannot read the configuration: " + errnoText(errno)});
    }
    std::string text;
    char buffer[8192];
    size_t count = 0;
    while ((count = std::fread(buffer, 1, sizeof buffer, file)) > 0) {
        text.append(buffer, count);
        if (static_cast<long>(text.size()) > kMaxBytes) {
            std::fclose(file);
            throw ConfigError({path + ": cannot read the configuration: larger than 1 MiB"});
        }
    }
    const bool failed = std::ferror(file) != 0;
    const int read_errno = errno;
    std::fclose(file);
    if (failed) {
        throw ConfigError({path + ": cannot read the configuration: " + errnoText(read_errno)});
    }
    return text;
}

} // namespace

ConfigError::ConfigError(std::vector<std::string> problems)
    : std::runtime_error(problems.empty() ? std::string("invalid configuration")
                                          : joinLines(problems)),
      problems_(std::move(problems)), keys_(problems_.size())
{
}

namespace {

std::vector<std::string> textsOf(const std::vector<ConfigProblem>& problems)
{
    std::vector<std::string> texts;
    texts.reserve(problems.size());
    for (const ConfigProblem& problem : problems)
        texts.push_back(problem.text);
    return texts;
}

} // namespace

ConfigError::ConfigError(const std::vector<ConfigProblem>& problems)
    : ConfigError(textsOf(problems))
{
    for (std::size_t i = 0; i < problems.size(); ++i)
        keys_[i] = problems[i].key;
}

bool ConfigError::onlyAbout(std::string_view key) const
{
    return !keys_.empty() && std::all_of(keys_.begin(), keys_.end(),
                                         [key](const std::string& k) { return k == key; });
}

ServiceConfig defaultConfig()
{
    ServiceConfig config;
    config.origin = "<defaults>";
    return config;
}

ServiceConfig loadConfig(const std::string& path)
{
    return loadConfig(path, ConfigOverrides{});
}

ServiceConfig loadConfig(const std::string& path, const ConfigOverrides& overrides)
{
    const std::string text = readConfigFile(path);
    ReadContext context;
    context.base_dir = fs::path(absolutePath(path)).parent_path();
    return parseDocument(text, path, context, overrides);
}

ServiceConfig parseConfig(const std::string& yaml_text, const std::string& origin)
{
    return parseDocument(yaml_text, origin, ReadContext{}, ConfigOverrides{});
}

void applyOverrides(ServiceConfig& config, const ConfigOverrides& overrides)
{
    KeyLocations unused;
    overrideKeys(config, overrides, unused);
}

void validateConfig(const ServiceConfig& config)
{
    validateConfig(config, ConfigOverrides{});
}

void validateConfig(const ServiceConfig& config, const ConfigOverrides& overrides)
{
    // Where each overridden value came from; the values themselves are in `config` already.
    ServiceConfig scratch = config;
    KeyLocations locations;
    overrideKeys(scratch, overrides, locations);
    auto problems = checkValues(config, locations);
    if (!problems.empty()) {
        throw ConfigError(inLineOrder(std::move(problems)));
    }
}

std::optional<LivePart> livePartOf(std::string_view key)
{
    const KeyDef* def = schema().find(key);
    if (def == nullptr || !def->live)
        return std::nullopt;
    const std::string_view section = key.substr(0, key.find('.'));
    if (section == "matcher" || section == "nearest" || section == "output" ||
        section == "point_cloud")
        return LivePart::Processing;
    if (section == "publish")
        return LivePart::Publish;
    if (section == "log_level")
        return LivePart::LogLevel;
    if (section == "calibration_health")
        return LivePart::CalibrationHealth;
    if (section == "robot" || section == "zones")
        return LivePart::Zones;
    return std::nullopt;
}

ConfigChange diffConfig(const ServiceConfig& running, const ServiceConfig& proposed)
{
    ConfigChange change;
    for (const auto& def : schema().keys) {
        if (def.show(running) == def.show(proposed)) {
            continue;
        }
        change.changed.push_back(def.path);
        const std::optional<LivePart> part = livePartOf(def.path);
        if (!part) {
            change.restart_needed.push_back(def.path);
        } else if (std::find(change.live_parts.begin(), change.live_parts.end(), *part) ==
                   change.live_parts.end()) {
            change.live_parts.push_back(*part);
        }
    }
    return change;
}

std::vector<ConfigKeyInfo> configKeys()
{
    std::vector<ConfigKeyInfo> keys;
    for (const auto& def : schema().keys) {
        keys.push_back(ConfigKeyInfo{def.path, def.live});
    }
    return keys;
}

std::optional<ListenAddress> parseListenAddress(const std::string& text)
{
    if (text == "off")
        return std::nullopt;
    const std::size_t colon = text.rfind(':');
    if (colon == std::string::npos || colon == 0 || colon + 1 == text.size())
        throw std::invalid_argument("\"" + text + "\" is not HOST:PORT");
    ListenAddress address;
    address.host = text.substr(0, colon);
    if (address.host.size() > 2 && address.host.front() == '[' && address.host.back() == ']')
        address.host = address.host.substr(1, address.host.size() - 2); // [::1]:8765
    const std::string port = text.substr(colon + 1);
    unsigned value = 0;
    const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
    if (ec != std::errc() || end != port.data() + port.size() || value > 65535)
        throw std::invalid_argument("port \"" + port + "\" is not a number from 0 to 65535");
    address.port = static_cast<uint16_t>(value);
    in6_addr scratch{};
    if (inet_pton(AF_INET, address.host.c_str(), &scratch) != 1 &&
        inet_pton(AF_INET6, address.host.c_str(), &scratch) != 1)
        throw std::invalid_argument("\"" + address.host + "\" is not an IP address");
    return address;
}

std::string formatListenAddress(const std::string& host, uint16_t port)
{
    const bool v6 = host.find(':') != std::string::npos;
    return (v6 ? "[" + host + "]" : host) + ":" + std::to_string(port);
}

bool isLoopbackHost(const std::string& host)
{
    in_addr v4{};
    if (inet_pton(AF_INET, host.c_str(), &v4) == 1)
        return (ntohl(v4.s_addr) >> 24) == 127;
    in6_addr v6{};
    return inet_pton(AF_INET6, host.c_str(), &v6) == 1 && IN6_IS_ADDR_LOOPBACK(&v6);
}

} // namespace stereod
