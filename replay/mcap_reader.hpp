#pragma once
// An MCAP reader: the file's schemas, channels and chunks, and its messages by chunk or
// one at a time by position.
//
// Opening reads the footer and, when the file has a summary with chunk indexes (and its
// CRC matches), takes schemas, channels, statistics and chunk positions from it without
// touching the data section. Otherwise (no summary: a writer killed mid-way, or a writer
// that writes none) it scans the data section from the start, record by record, and
// stops at the first record that is incomplete or corrupt (a chunk that does not
// decompress or whose CRC differs): every complete chunk before it is readable,
// truncated() is true and problem() says where it stopped.
//
// Supported: chunks compressed with zstd or not compressed, messages in chunks or in the
// data section. lz4 chunks are refused with a clear error (ROS 2 writes zstd or none).
//
// Thread-bound: one thread reads; the reader keeps the last decompressed chunk.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "base/unique_fd.hpp"
#include "replay/mcap_records.hpp"

namespace stereod::mcap {

// Where a message lives: inside chunk `chunk` at `offset` in its uncompressed records,
// or, when chunk == kNoChunk, a Message record in the data section at file offset `offset`.
struct MessageRef {
    static constexpr uint32_t kNoChunk = 0xFFFFFFFF;
    uint32_t chunk = kNoChunk;
    uint64_t offset = 0;
};

class Reader {
  public:
    // Opens and indexes `path`. Throws McapError: ENOENT/EACCES when it cannot be opened,
    // EINVAL when it is not MCAP (no magic, no Header) or nothing past the Header parses.
    explicit Reader(const std::string& path);
    ~Reader();

    Reader(const Reader&) = delete;
    Reader& operator=(const Reader&) = delete;

    const Header& header() const noexcept { return header_; }
    const std::map<uint16_t, Schema>& schemas() const noexcept { return schemas_; }
    const std::map<uint16_t, Channel>& channels() const noexcept { return channels_; }
    // Chunks in file order (from the summary, or found by the scan).
    const std::vector<ChunkIndex>& chunks() const noexcept { return chunks_; }
    // From the summary; absent when the file has none (then count with forEachMessage).
    const Statistics* statistics() const noexcept
    {
        return has_statistics_ ? &statistics_ : nullptr;
    }

    // True when the index came from the summary section.
    bool hasSummary() const noexcept { return from_summary_; }
    // True when the scan stopped before a Data End record: the file was cut short (or is
    // corrupt from problem()'s offset on).
    bool truncated() const noexcept { return truncated_; }
    const std::string& problem() const noexcept { return problem_; }
    const std::string& path() const noexcept { return path_; }

    // Calls f(message, ref) for every message in file order: chunk by chunk (each chunk's
    // records in their order), and the data section's own Message records in between.
    // The message's data is valid only during the call. A chunk that does not decompress,
    // or whose records break off, is skipped from there on and named in skippedChunks():
    // one damaged chunk does not cost the others. Throws what `f` throws, and McapError
    // for a Message record outside chunks that cannot be read.
    void forEachMessage(const std::function<void(const MessageView&, const MessageRef&)>& f);
    // The chunks forEachMessage() skipped, each with where it is and why, once each.
    const std::vector<std::string>& skippedChunks() const noexcept { return skipped_chunks_; }

    // The message at `ref` (from forEachMessage). Its data stays valid until the next call
    // to any member function. Decompresses the chunk unless it is the last one used.
    // Throws McapError.
    MessageView message(const MessageRef& ref);

  private:
    bool readSummary(uint64_t file_size);
    void scan(uint64_t file_size);
    // Reads [offset, offset + size) into `out`; false when the file is shorter.
    bool readAt(uint64_t offset, uint64_t size, std::string& out) const;
    void addSchema(Schema schema);
    void addChannel(Channel channel);
    // Makes chunk `i`'s uncompressed records current in chunk_records_.
    const std::string& loadChunk(uint32_t i);

    std::string path_;
    UniqueFd fd_;
    uint64_t file_size_ = 0; // as opened (a file still growing is read up to this)
    Header header_;
    std::map<uint16_t, Schema> schemas_;
    std::map<uint16_t, Channel> channels_;
    std::vector<ChunkIndex> chunks_;
    std::vector<uint64_t> loose_messages_; // file offsets of Message records outside chunks
    Statistics statistics_;
    bool has_statistics_ = false;
    bool from_summary_ = false;
    bool truncated_ = false;
    std::string problem_;

    std::vector<std::string> skipped_chunks_;
    // forEachMessage(): the messages of the chunk at hand, parsed before any is handed out.
    std::vector<std::pair<MessageView, MessageRef>> chunk_messages_;

    uint32_t loaded_chunk_ = MessageRef::kNoChunk;
    std::string chunk_records_; // uncompressed records of loaded_chunk_
    std::string raw_;           // scratch: bytes read from the file
};

} // namespace stereod::mcap
