#include "ros2/topic_names.hpp"

namespace stereod::ros2 {

namespace {

bool isTokenChar(char c)
{
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
}

} // namespace

std::string namespaceProblem(std::string_view ns)
{
    // rmw's topic names are at most 255 characters with the "rt" prefix and the longest
    // topic ("/right/camera_info") after the namespace.
    constexpr std::size_t kMaxLength = 200;
    if (ns.empty() || ns.front() != '/')
        return "must start with '/'";
    if (ns.size() > kMaxLength)
        return "longer than " + std::to_string(kMaxLength) + " characters";
    if (ns == "/")
        return {};
    if (ns.back() == '/')
        return "must not end with '/'";
    bool token_start = true;
    for (std::size_t i = 1; i < ns.size(); ++i) {
        const char c = ns[i];
        if (c == '/') {
            if (token_start)
                return "has an empty name between two '/'";
            token_start = true;
            continue;
        }
        if (!isTokenChar(c))
            return std::string("has '") + c + "': only letters, digits, '_' and '/' are allowed";
        if (token_start && c >= '0' && c <= '9')
            return "has a name that starts with a digit";
        token_start = false;
    }
    return {};
}

std::string rosTopicName(std::string_view ns, std::string_view relative)
{
    std::string name(ns);
    if (name.back() != '/')
        name += '/';
    name += relative;
    return name;
}

std::string ddsTopicName(std::string_view ros_name)
{
    return "rt" + std::string(ros_name);
}

std::string cameraInfoTopicBeside(std::string_view image_topic)
{
    const auto slash = image_topic.rfind('/');
    return (slash == std::string_view::npos ? std::string()
                                            : std::string(image_topic.substr(0, slash + 1))) +
           "camera_info";
}

} // namespace stereod::ros2
