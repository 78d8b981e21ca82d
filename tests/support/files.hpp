#pragma once
// Reading a file back whole, and the message of an expected refusal. Reentrant.

#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>

#include <gtest/gtest.h>
#include <unistd.h>

namespace stereod::test {

// The whole content of a file; empty when it cannot be read.
inline std::string readFile(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Runs `run`, which must throw an `Error`; returns its message (a test failure, and "",
// when nothing is thrown).
template <typename Error> std::string refusalMessage(const std::function<void()>& run)
{
    try {
        run();
    } catch (const Error& error) {
        return error.what();
    }
    ADD_FAILURE() << "no refusal";
    return {};
}

inline bool contains(const std::string& text, const std::string& part)
{
    return text.find(part) != std::string::npos;
}

} // namespace stereod::test
