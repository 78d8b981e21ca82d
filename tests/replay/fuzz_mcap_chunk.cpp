// libFuzzer target: a bag's zstd chunk. The input is the chunk's stated uncompressed size
// (8 bytes, little-endian) then its compressed records; the records it gives are walked as
// the reader walks them (messages, their Image payloads). A chunk either gives exactly the
// size it states or is refused with McapError; nothing crashes, and nothing is allocated
// beyond what the frame's blocks can really give (the fuzzer's RSS limit is the check).
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "replay/mcap_records.hpp"
#include "ros2/messages.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    using namespace stereod;
    if (size < 8)
        return 0;
    mcap::ChunkView chunk;
    std::memcpy(&chunk.uncompressed_size, data, 8); // little-endian hosts, as the reader
    chunk.compression = "zstd";
    chunk.records = std::string_view(reinterpret_cast<const char*>(data) + 8, size - 8);
    std::string records;
    try {
        mcap::decompressChunk(chunk, records);
    } catch (const mcap::McapError&) {
        return 0;
    }
    if (records.size() != chunk.uncompressed_size)
        __builtin_trap();
    try {
        mcap::forEachRecord(records, [](mcap::Op op, std::string_view content, std::size_t) {
            if (op != mcap::Op::Message)
                return;
            const mcap::MessageView message = mcap::parseMessage(content);
            try {
                ros2::parseImage(message.data);
            } catch (const ros2::CdrError&) {
            }
        });
    } catch (const mcap::McapError&) {
    }
    return 0;
}
