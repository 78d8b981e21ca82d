#pragma once
// An MCAP writer (replay/mcap_records.hpp has the layout it writes).
//
// Every message goes into a chunk; a chunk is closed, compressed (zstd, or not) and
// written with its Message Index records in one write() as soon as its uncompressed
// records reach `chunk_size_bytes` or `chunk_messages` messages. Schema and Channel
// records go to the data section, outside chunks, the moment they are added. So a writer
// killed at any point (kill -9, power, a full disk) leaves a file whose every complete
// chunk is readable by McapReader's scan (and by other readers that scan, e.g. `mcap
// recover`); at most the open chunk is lost. close() writes Data End, the summary
// (schemas, channels, statistics, chunk indexes), the summary offsets and the footer, so
// readers can seek.
//
// Errors: a failed write throws McapError with the errno (ENOSPC, EIO, ...) and the
// file's name; the writer is then unusable (every later call throws) and the file keeps
// what was written before.
//
// Thread-bound: one thread writes; the writer is not shared.

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "base/unique_fd.hpp"
#include "replay/mcap_records.hpp"

namespace stereod::mcap {

struct WriterOptions {
    enum class Compression { None, Zstd };

    std::string profile; // "ros2" for ROS 2 bags, or empty
    std::string library = "stereod";
    Compression compression = Compression::Zstd;
    // zstd level: 1 is the fastest (about 300 MB/s of camera images per core) and already
    // takes most of what zstd can take from raw images.
    int zstd_level = 1;
    // A chunk is closed once its uncompressed records reach this size or this many
    // messages: what a killed writer can lose at most. 4 MiB holds about six 640x480
    // mono8 images.
    std::size_t chunk_size_bytes = 4u << 20;
    std::size_t chunk_messages = 1000;
};

class Writer {
  public:
    // Creates `path` (never overwrites: EEXIST when it exists) and writes the magic and
    // the Header. Throws McapError.
    Writer(const std::string& path, WriterOptions options);
    // Closes the file as close() does; errors are logged to stderr, not thrown.
    ~Writer();

    Writer(const Writer&) = delete;
    Writer& operator=(const Writer&) = delete;

    // Adds a schema (written at once) and returns its id (1, 2, ...).
    uint16_t addSchema(const std::string& name, const std::string& encoding,
                       const std::string& data);
    // Adds a channel on `schema_id` (0: none, else an id from addSchema) and returns its
    // id (0, 1, ...). Throws McapError (EINVAL) for an unknown schema.
    uint16_t addChannel(uint16_t schema_id, const std::string& topic,
                        const std::string& message_encoding,
                        const std::map<std::string, std::string>& metadata = {});

    // Appends one message to the open chunk (and writes the chunk when it is full).
    // Times in ns on the recording's clock. Throws McapError.
    void write(uint16_t channel_id, uint64_t log_time_ns, uint64_t publish_time_ns,
               std::string_view data, uint32_t sequence = 0);

    // Writes the open chunk now, if it holds anything.
    void flushChunk();

    // Writes the open chunk, Data End, the summary and the footer, and closes the file
    // (fsync'ed first). Throws McapError. Idempotent.
    void close();

    uint64_t messagesWritten() const noexcept { return statistics_.message_count; }
    // Messages of `channel_id` in chunks written to the file: what a reader finds even if
    // the open chunk never is (a full disk, a kill).
    uint64_t messagesOnDisk(uint16_t channel_id) const noexcept;
    uint64_t bytesWritten() const noexcept { return position_; }
    // Uncompressed bytes of all message records so far (for compression ratios).
    uint64_t uncompressedBytes() const noexcept { return uncompressed_bytes_; }
    const std::string& path() const noexcept { return path_; }

  private:
    // Writes `bytes` at the end of the file; counts them into the data-section CRC while
    // the data section is open.
    void append(std::string_view bytes);
    void checkUsable() const;

    std::string path_;
    WriterOptions options_;
    UniqueFd fd_;
    bool failed_ = false;
    bool closed_ = false;
    uint64_t position_ = 0; // bytes in the file
    uint32_t data_crc_ = 0; // CRC of the data section so far
    bool data_section_open_ = true;

    std::vector<Schema> schemas_;
    std::vector<Channel> channels_;
    std::vector<ChunkIndex> chunk_indexes_;
    Statistics statistics_;
    uint64_t uncompressed_bytes_ = 0;

    // The open chunk: its uncompressed records, message count and time range, and per
    // channel the (log_time, offset in records) of its messages. Buffers keep their
    // capacity from chunk to chunk.
    std::string chunk_records_;
    std::size_t chunk_message_count_ = 0;
    uint64_t chunk_start_time_ = 0;
    uint64_t chunk_end_time_ = 0;
    std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_message_index_;
    std::map<uint16_t, uint64_t> flushed_messages_; // per channel, in chunks written
    std::string compressed_;                        // scratch: compressed records
    std::string out_; // scratch: chunk + message index records as written
};

} // namespace stereod::mcap
