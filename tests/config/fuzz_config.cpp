// libFuzzer entry point for the configuration loader: any bytes must give either a
// configuration or a ConfigError, never a crash, a hang or another exception.
//
// Not part of the normal build. The loader needs nothing from the pipeline but its
// headers, so from the project root, with clang:
//   clang++ -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -I. -I/usr/include/opencv4
//       tests/config/fuzz_config.cpp config/service_config.cpp -lyaml-cpp -o fuzz_config
//   ./fuzz_config -max_len=4096 -dict=tests/config/fuzz_config.dict corpus/

#include <cstddef>
#include <cstdint>
#include <string>

#include "config/service_config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        const stereod::ServiceConfig config = stereod::parseConfig(text, "<fuzz>");
        // A configuration that was accepted must pass its own validation and compare
        // equal to itself.
        stereod::validateConfig(config);
        if (!stereod::diffConfig(config, config).changed.empty()) {
            __builtin_trap();
        }
    } catch (const stereod::ConfigError& error) {
        if (error.problems().empty()) {
            __builtin_trap();
        }
    }
    return 0;
}
