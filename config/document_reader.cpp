#include "config/document_reader.hpp"

#include <algorithm>
#include <limits>

#include "config/key_table.hpp"

namespace stereod::config_detail {

std::vector<ConfigProblem> inLineOrder(std::vector<Problem> problems)
{
    std::stable_sort(problems.begin(), problems.end(), [](const Problem& a, const Problem& b) {
        const auto order = [](int line) {
            return line > 0 ? line : std::numeric_limits<int>::max();
        };
        return order(a.line) < order(b.line);
    });
    std::vector<ConfigProblem> ordered;
    for (auto& problem : problems) {
        ordered.push_back(ConfigProblem{std::move(problem.key), std::move(problem.text)});
    }
    return ordered;
}

namespace {

// Reads one parsed document into a configuration, noting every problem. One per call,
// thread-bound.
class DocumentReader {
  public:
    DocumentReader(std::string origin, ReadContext context, ServiceConfig& config,
                   KeyLocations& locations, std::vector<Problem>& problems)
        : origin_(std::move(origin)), context_(std::move(context)), config_(config),
          locations_(locations), problems_(problems)
    {
    }

    void read(const YAML::Node& root) { readSection(root, schema().root, "", root.Mark()); }

  private:
    void report(const YAML::Mark& mark, const std::string& key, std::string_view problem,
                std::string_view detail)
    {
        std::string message = origin_;
        if (!mark.is_null()) {
            message += ":" + std::to_string(mark.line + 1);
        }
        message += ": ";
        if (!key.empty()) {
            message += key + ": ";
        }
        message += problem;
        if (!detail.empty()) {
            message += " (" + std::string(detail) + ")";
        }
        problems_.push_back(Problem{mark.is_null() ? 0 : mark.line + 1, key, std::move(message)});
    }

    void readSection(const YAML::Node& node, const SchemaNode& section, const std::string& prefix,
                     const YAML::Mark& mark)
    {
        if (node.IsNull()) {
            return; // an empty section ("nearest:" and nothing under it) keeps the defaults
        }
        if (!node.IsMap()) {
            report(mark, prefix, prefix.empty() ? "not a mapping of keys" : "not a section",
                   "got " + describeNode(node) + ", expected a mapping of keys");
            locations_.unreadable.insert(prefix);
            return;
        }
        std::map<std::string, int> seen; // key -> line of its first appearance
        for (const auto& item : node) {
            // Copies: the iterator hands out temporaries (Nodes are handles, cheap to copy).
            const YAML::Node key_node = item.first;
            const YAML::Node value = item.second;
            const YAML::Mark key_mark = key_node.Mark();
            if (!key_node.IsScalar()) {
                report(key_mark, prefix, "a key that is not a name",
                       "got " + describeNode(key_node));
                continue;
            }
            const std::string& name = key_node.Scalar();
            const std::string path = joinPath(prefix, name);
            const auto [first, inserted] = seen.emplace(name, key_mark.line + 1);
            if (!inserted) {
                report(key_mark, path, "given twice",
                       "first on line " + std::to_string(first->second) + "; remove one");
                continue;
            }
            const SchemaNode* entry = section.child(name);
            if (entry == nullptr) {
                reportUnknownKey(key_mark, section, prefix, name);
                continue;
            }
            locations_.lines[path] = key_mark.line + 1;
            if (entry->key == nullptr) {
                readSection(value, *entry, path, key_mark);
                continue;
            }
            if (auto failure = entry->key->read(value, config_, context_)) {
                report(key_mark, path, failure->problem,
                       "got " + describeNode(value) + ", expected " + failure->expected);
                locations_.unreadable.insert(path);
            }
        }
    }

    void reportUnknownKey(const YAML::Mark& mark, const SchemaNode& section,
                          const std::string& prefix, const std::string& name)
    {
        std::vector<std::string> siblings;
        for (const auto& entry : section.children) {
            siblings.push_back(entry.name);
        }
        const std::string path = joinPath(prefix, name);
        if (auto suggestion = closestName(name, siblings)) {
            report(mark, path, "unknown key", "did you mean " + *suggestion + "?");
            return;
        }
        // A known key in the wrong section ("min_pixels" under "matcher").
        std::vector<std::string> elsewhere;
        for (const auto& def : schema().keys) {
            const size_t dot = def.path.rfind('.');
            const std::string leaf = dot == std::string::npos ? def.path : def.path.substr(dot + 1);
            if (normalizedName(leaf) == normalizedName(name)) {
                elsewhere.push_back(def.path);
            }
        }
        if (!elsewhere.empty()) {
            report(mark, path, "unknown key", "did you mean " + listNames(elsewhere) + "?");
            return;
        }
        report(mark, path, "unknown key", "known keys here: " + listNames(siblings));
    }

    std::string origin_;
    ReadContext context_;
    ServiceConfig& config_;
    KeyLocations& locations_;
    std::vector<Problem>& problems_;
};
} // namespace

void readDocument(const YAML::Node& root, const std::string& origin, const ReadContext& context,
                  ServiceConfig& config, KeyLocations& locations, std::vector<Problem>& problems)
{
    DocumentReader(origin, context, config, locations, problems).read(root);
}

} // namespace stereod::config_detail
