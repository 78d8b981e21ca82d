#include "replay/mcap_writer.hpp"

#include <cstdio>
#include <cstring>

#include <fcntl.h>
#include <unistd.h>

#include "base/system_error.hpp"

namespace stereod::mcap {

namespace {

std::string errnoMessage(const std::string& path, const char* action, int code)
{
    return path + ": " + action + ": " + errnoText(code);
}

} // namespace

Writer::Writer(const std::string& path, WriterOptions options)
    : path_(path), options_(std::move(options))
{
    fd_.reset(::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644));
    if (!fd_.valid()) {
        const int code = errno;
        throw McapError(errnoMessage(path, "cannot create", code), code);
    }
    std::string start(reinterpret_cast<const char*>(kMagic), kMagicSize);
    ByteWriter w(start);
    writeHeader(w, Header{options_.profile, options_.library});
    append(start);
}

Writer::~Writer()
{
    try {
        close();
    } catch (const McapError& e) {
        std::fprintf(stderr, "mcap: %s\n", e.what());
    }
}

void Writer::checkUsable() const
{
    if (failed_) {
        throw McapError(path_ + ": an earlier write failed; the file holds what was written before",
                        EIO);
    }
    if (closed_) {
        throw McapError(path_ + ": already closed", EINVAL);
    }
}

void Writer::append(std::string_view bytes)
{
    const char* p = bytes.data();
    std::size_t left = bytes.size();
    while (left > 0) {
        const ssize_t n = ::write(fd_.get(), p, left);
        if (n < 0) {
            if (errno == EINTR) {
                continue;
            }
            const int code = errno;
            failed_ = true;
            throw McapError(errnoMessage(path_, "write failed", code), code);
        }
        p += n;
        left -= static_cast<std::size_t>(n);
    }
    if (data_section_open_) {
        data_crc_ = crc32(data_crc_, bytes.data(), bytes.size());
    }
    position_ += bytes.size();
}

uint16_t Writer::addSchema(const std::string& name, const std::string& encoding,
                           const std::string& data)
{
    checkUsable();
    Schema schema{static_cast<uint16_t>(schemas_.size() + 1), name, encoding, data};
    out_.clear();
    ByteWriter w(out_);
    writeSchema(w, schema);
    append(out_);
    schemas_.push_back(std::move(schema));
    return schemas_.back().id;
}

uint16_t Writer::addChannel(uint16_t schema_id, const std::string& topic,
                            const std::string& message_encoding,
                            const std::map<std::string, std::string>& metadata)
{
    checkUsable();
    if (schema_id > schemas_.size()) {
        throw McapError(path_ + ": channel '" + topic + "' refers to unknown schema " +
                        std::to_string(schema_id));
    }
    Channel channel{static_cast<uint16_t>(channels_.size()), schema_id, topic, message_encoding,
                    metadata};
    out_.clear();
    ByteWriter w(out_);
    writeChannel(w, channel);
    append(out_);
    channels_.push_back(std::move(channel));
    return channels_.back().id;
}

void Writer::write(uint16_t channel_id, uint64_t log_time_ns, uint64_t publish_time_ns,
                   std::string_view data, uint32_t sequence)
{
    checkUsable();
    if (channel_id >= channels_.size()) {
        throw McapError(path_ + ": message on unknown channel " + std::to_string(channel_id));
    }
    const uint64_t offset = chunk_records_.size();
    ByteWriter w(chunk_records_);
    writeMessage(w, MessageView{channel_id, sequence, log_time_ns, publish_time_ns, data});
    uncompressed_bytes_ += chunk_records_.size() - offset;
    chunk_message_index_[channel_id].emplace_back(log_time_ns, offset);
    if (chunk_message_count_ == 0 || log_time_ns < chunk_start_time_) {
        chunk_start_time_ = log_time_ns;
    }
    if (chunk_message_count_ == 0 || log_time_ns > chunk_end_time_) {
        chunk_end_time_ = log_time_ns;
    }
    ++chunk_message_count_;

    Statistics& s = statistics_;
    if (s.message_count == 0 || log_time_ns < s.message_start_time) {
        s.message_start_time = log_time_ns;
    }
    if (s.message_count == 0 || log_time_ns > s.message_end_time) {
        s.message_end_time = log_time_ns;
    }
    ++s.message_count;
    ++s.channel_message_counts[channel_id];

    if (chunk_records_.size() >= options_.chunk_size_bytes ||
        chunk_message_count_ >= options_.chunk_messages) {
        flushChunk();
    }
}

void Writer::flushChunk()
{
    checkUsable();
    if (chunk_message_count_ == 0) {
        return;
    }
    const bool zstd = options_.compression == WriterOptions::Compression::Zstd;
    std::string_view stored = chunk_records_;
    if (zstd) {
        zstdCompress(chunk_records_, compressed_, options_.zstd_level);
        stored = compressed_;
    }

    ChunkIndex index;
    index.message_start_time = chunk_start_time_;
    index.message_end_time = chunk_end_time_;
    index.chunk_start_offset = position_;
    index.compression = zstd ? "zstd" : "";
    index.compressed_size = stored.size();
    index.uncompressed_size = chunk_records_.size();

    out_.clear();
    ByteWriter w(out_);
    writeChunk(w, ChunkView{chunk_start_time_, chunk_end_time_, chunk_records_.size(),
                            crc32(0, chunk_records_.data(), chunk_records_.size()),
                            index.compression, stored});
    index.chunk_length = out_.size();

    // One Message Index per channel of the chunk, in channel order.
    for (const auto& [channel, entries] : chunk_message_index_) {
        if (entries.empty()) {
            continue;
        }
        index.message_index_offsets[channel] = position_ + out_.size();
        const auto mi = w.beginRecord(Op::MessageIndex);
        w.u16(channel);
        w.u32(static_cast<uint32_t>(entries.size() * 16));
        for (const auto& [time, offset] : entries) {
            w.u64(time);
            w.u64(offset);
        }
        w.endRecord(mi);
    }
    index.message_index_length = out_.size() - index.chunk_length;

    append(out_);
    chunk_indexes_.push_back(std::move(index));
    ++statistics_.chunk_count;

    chunk_records_.clear();
    chunk_message_count_ = 0;
    for (auto& [channel, entries] : chunk_message_index_) {
        flushed_messages_[channel] += entries.size(); // on disk now (append() returned)
        entries.clear();
    }
}

uint64_t Writer::messagesOnDisk(uint16_t channel_id) const noexcept
{
    const auto it = flushed_messages_.find(channel_id);
    return it == flushed_messages_.end() ? 0 : it->second;
}

void Writer::close()
{
    if (closed_ || !fd_.valid()) {
        return;
    }
    if (failed_) {
        closed_ = true;
        return;
    }
    flushChunk();

    out_.clear();
    ByteWriter w(out_);
    const auto de = w.beginRecord(Op::DataEnd);
    w.u32(data_crc_);
    w.endRecord(de);
    append(out_);
    data_section_open_ = false;

    // The summary, grouped by opcode, with one Summary Offset per group.
    const uint64_t summary_start = position_;
    out_.clear();
    struct Group {
        Op op;
        uint64_t start;
        uint64_t length;
    };
    std::vector<Group> groups;
    auto group = [&](Op op, auto&& write_records) {
        const std::size_t begin = out_.size();
        write_records();
        if (out_.size() > begin) {
            groups.push_back({op, summary_start + begin, out_.size() - begin});
        }
    };
    group(Op::Schema, [&] {
        for (const auto& s : schemas_) {
            writeSchema(w, s);
        }
    });
    group(Op::Channel, [&] {
        for (const auto& c : channels_) {
            writeChannel(w, c);
        }
    });
    statistics_.schema_count = static_cast<uint16_t>(schemas_.size());
    statistics_.channel_count = static_cast<uint32_t>(channels_.size());
    group(Op::Statistics, [&] { writeStatistics(w, statistics_); });
    group(Op::ChunkIndex, [&] {
        for (const auto& c : chunk_indexes_) {
            writeChunkIndex(w, c);
        }
    });
    const uint64_t summary_offset_start = summary_start + out_.size();
    for (const auto& g : groups) {
        const auto so = w.beginRecord(Op::SummaryOffset);
        w.u8(static_cast<uint8_t>(g.op));
        w.u64(g.start);
        w.u64(g.length);
        w.endRecord(so);
    }
    // The footer's CRC covers the summary, the summary offsets and the footer up to (not
    // including) the CRC itself.
    w.u8(static_cast<uint8_t>(Op::Footer));
    w.u64(kFooterContentSize);
    w.u64(summary_start);
    w.u64(summary_offset_start);
    w.u32(crc32(0, out_.data(), out_.size()));
    w.bytes(std::string_view(reinterpret_cast<const char*>(kMagic), kMagicSize));
    append(out_);

    closed_ = true;
    if (::fsync(fd_.get()) != 0 && errno != EINVAL) {
        const int code = errno;
        throw McapError(errnoMessage(path_, "fsync failed", code), code);
    }
    // Closed here, not by UniqueFd, so that a failing close() is reported.
    if (::close(fd_.release()) != 0) {
        const int code = errno;
        throw McapError(errnoMessage(path_, "close failed", code), code);
    }
}

} // namespace stereod::mcap
