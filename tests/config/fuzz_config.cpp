// libFuzzer entry point for the configuration loader: any bytes must give either a
// configuration or a ConfigError, never a crash, a hang or another exception.
//
// Built with clang by tests/fuzz/CMakeLists.txt and run by scripts/fuzz.sh [SECONDS]
// from the seeds in tests/fuzz/corpus/config/ with tests/config/fuzz_config.dict.

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
