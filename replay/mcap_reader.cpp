#include "replay/mcap_reader.hpp"

#include <algorithm>
#include <cstring>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/system_error.hpp"

namespace stereod::mcap {

namespace {

std::string_view magicView()
{
    return {reinterpret_cast<const char*>(kMagic), kMagicSize};
}

} // namespace

Reader::Reader(const std::string& path) : path_(path)
{
    fd_.reset(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    if (!fd_.valid()) {
        const int code = errno;
        throw McapError(path + ": cannot open: " + errnoText(code), code);
    }
    struct stat st {};
    if (::fstat(fd_.get(), &st) != 0) {
        const int code = errno;
        throw McapError(path + ": cannot stat: " + errnoText(code), code);
    }
    const auto file_size = static_cast<uint64_t>(st.st_size);
    file_size_ = file_size;
    try {
        std::string start;
        if (!readAt(0, kMagicSize + kRecordPrefixSize, start) ||
            std::string_view(start).substr(0, kMagicSize) != magicView() ||
            static_cast<Op>(start[kMagicSize]) != Op::Header) {
            throw McapError(path + ": not an MCAP file (no MCAP magic and Header at the start)");
        }
        ByteReader prefix(std::string_view(start).substr(kMagicSize + 1), "Header");
        const uint64_t header_length = prefix.u64();
        std::string content;
        if (!readAt(kMagicSize + kRecordPrefixSize, header_length, content)) {
            throw McapError(path + ": the Header record is cut short");
        }
        header_ = parseHeader(content);
        if (!readSummary(file_size)) {
            scan(file_size);
        }
    } catch (...) {
        fd_.reset();
        throw;
    }
}

Reader::~Reader() = default;

bool Reader::readAt(uint64_t offset, uint64_t size, std::string& out) const
{
    // Lengths come from the file: one past its end is damage, not a reason to allocate.
    if (offset > file_size_ || size > file_size_ - offset) {
        return false;
    }
    out.resize(size);
    uint64_t done = 0;
    while (done < size) {
        const ssize_t n =
            ::pread(fd_.get(), out.data() + done, size - done, static_cast<off_t>(offset + done));
        if (n < 0) {
            if (errno == EINTR) {
                continue;
            }
            const int code = errno;
            throw McapError(path_ + ": read failed: " + errnoText(code), code);
        }
        if (n == 0) {
            return false;
        }
        done += static_cast<uint64_t>(n);
    }
    return true;
}

void Reader::addSchema(Schema schema)
{
    if (schema.id != 0) {
        schemas_.insert_or_assign(schema.id, std::move(schema));
    }
}

void Reader::addChannel(Channel channel)
{
    channels_.insert_or_assign(channel.id, std::move(channel));
}

bool Reader::readSummary(uint64_t file_size)
{
    const uint64_t tail_size = kRecordPrefixSize + kFooterContentSize + kMagicSize;
    if (file_size < kMagicSize * 2 + tail_size) {
        return false;
    }
    const uint64_t footer_offset = file_size - tail_size;
    std::string tail;
    if (!readAt(footer_offset, tail_size, tail)) {
        return false;
    }
    const std::string_view t = tail;
    if (t.substr(tail_size - kMagicSize) != magicView() || static_cast<Op>(t[0]) != Op::Footer) {
        return false;
    }
    ByteReader fr(t.substr(1), "Footer");
    if (fr.u64() != kFooterContentSize) {
        return false;
    }
    const Footer footer = parseFooter(t.substr(kRecordPrefixSize, kFooterContentSize));
    if (footer.summary_start == 0 || footer.summary_start >= footer_offset) {
        return false;
    }
    std::string summary;
    if (!readAt(footer.summary_start, footer_offset - footer.summary_start, summary)) {
        return false;
    }
    if (footer.summary_crc != 0) {
        uint32_t crc = crc32(0, summary.data(), summary.size());
        crc = crc32(crc, tail.data(), kRecordPrefixSize + 16);
        if (crc != footer.summary_crc) {
            problem_ = "summary CRC mismatch; scanned the data section instead";
            return false;
        }
    }
    const uint64_t summary_end = footer.summary_offset_start != 0
                                     ? footer.summary_offset_start - footer.summary_start
                                     : summary.size();
    std::map<uint16_t, Schema> schemas;
    std::map<uint16_t, Channel> channels;
    std::vector<ChunkIndex> chunks;
    try {
        forEachRecord(std::string_view(summary).substr(0, summary_end),
                      [&](Op op, std::string_view content, std::size_t) {
                          switch (op) {
                          case Op::Schema: {
                              Schema s = parseSchema(content);
                              if (s.id != 0) {
                                  schemas.insert_or_assign(s.id, std::move(s));
                              }
                              break;
                          }
                          case Op::Channel: {
                              Channel c = parseChannel(content);
                              channels.insert_or_assign(c.id, std::move(c));
                              break;
                          }
                          case Op::ChunkIndex:
                              chunks.push_back(parseChunkIndex(content));
                              break;
                          case Op::Statistics:
                              statistics_ = parseStatistics(content);
                              has_statistics_ = true;
                              break;
                          default:
                              break; // attachment and metadata indexes: not used
                          }
                      });
    } catch (const McapError& e) {
        problem_ =
            std::string("summary unreadable (") + e.what() + "); scanned the data section instead";
        has_statistics_ = false;
        return false;
    }
    if (chunks.empty() && (!has_statistics_ || statistics_.message_count > 0)) {
        // No chunk index: the messages are outside chunks or unindexed; only a scan finds them.
        has_statistics_ = false;
        return false;
    }
    std::sort(chunks.begin(), chunks.end(), [](const ChunkIndex& a, const ChunkIndex& b) {
        return a.chunk_start_offset < b.chunk_start_offset;
    });
    schemas_ = std::move(schemas);
    channels_ = std::move(channels);
    chunks_ = std::move(chunks);
    from_summary_ = true;
    return true;
}

void Reader::scan(uint64_t file_size)
{
    uint64_t pos = kMagicSize;
    std::string prefix;
    std::string content;
    bool first = true;
    while (true) {
        if (!readAt(pos, kRecordPrefixSize, prefix)) {
            truncated_ = true;
            problem_ = "file ends at byte " + std::to_string(file_size) +
                       " without a Data End record (cut short: a recording that was not closed)";
            return;
        }
        const auto op = static_cast<Op>(prefix[0]);
        ByteReader pr(std::string_view(prefix).substr(1), "record");
        const uint64_t length = pr.u64();
        if (length > file_size - pos - kRecordPrefixSize) {
            truncated_ = true;
            problem_ = "record at byte " + std::to_string(pos) +
                       " runs past the end of the file (" + std::to_string(file_size) +
                       " bytes): cut short";
            return;
        }
        if (first) {
            first = false; // the Header, already read
            pos += kRecordPrefixSize + length;
            continue;
        }
        if (op == Op::DataEnd || op == Op::Footer) {
            return;
        }
        try {
            switch (op) {
            case Op::Schema:
                readAt(pos + kRecordPrefixSize, length, content);
                addSchema(parseSchema(content));
                break;
            case Op::Channel:
                readAt(pos + kRecordPrefixSize, length, content);
                addChannel(parseChannel(content));
                break;
            case Op::Message:
                loose_messages_.push_back(pos);
                break;
            case Op::Chunk: {
                readAt(pos + kRecordPrefixSize, length, content);
                const ChunkView view = parseChunk(content);
                decompressChunk(view, chunk_records_);
                // Schemas and channels may live inside chunks.
                forEachRecord(chunk_records_, [&](Op inner, std::string_view c, std::size_t) {
                    if (inner == Op::Schema) {
                        addSchema(parseSchema(c));
                    } else if (inner == Op::Channel) {
                        addChannel(parseChannel(c));
                    }
                });
                ChunkIndex index;
                index.message_start_time = view.message_start_time;
                index.message_end_time = view.message_end_time;
                index.chunk_start_offset = pos;
                index.chunk_length = kRecordPrefixSize + length;
                index.compression = view.compression;
                index.compressed_size = view.records.size();
                index.uncompressed_size = view.uncompressed_size;
                chunks_.push_back(std::move(index));
                loaded_chunk_ = static_cast<uint32_t>(chunks_.size() - 1);
                break;
            }
            default:
                break; // message indexes, attachments, metadata, private records
            }
        } catch (const McapError& e) {
            truncated_ = true;
            problem_ = "record at byte " + std::to_string(pos) + " is corrupt (" + e.what() +
                       "): read up to it";
            return;
        }
        pos += kRecordPrefixSize + length;
    }
}

const std::string& Reader::loadChunk(uint32_t i)
{
    if (loaded_chunk_ != i) {
        const ChunkIndex& index = chunks_.at(i);
        if (index.chunk_length < kRecordPrefixSize ||
            !readAt(index.chunk_start_offset + kRecordPrefixSize,
                    index.chunk_length - kRecordPrefixSize, raw_)) {
            throw McapError(path_ + ": chunk at byte " + std::to_string(index.chunk_start_offset) +
                            " lies past the end of the file");
        }
        loaded_chunk_ = MessageRef::kNoChunk;
        decompressChunk(parseChunk(raw_), chunk_records_);
        loaded_chunk_ = i;
    }
    return chunk_records_;
}

void Reader::forEachMessage(const std::function<void(const MessageView&, const MessageRef&)>& f)
{
    std::size_t loose = 0;
    for (uint32_t i = 0; i < chunks_.size(); ++i) {
        for (; loose < loose_messages_.size() &&
               loose_messages_[loose] < chunks_[i].chunk_start_offset;
             ++loose) {
            const MessageRef ref{MessageRef::kNoChunk, loose_messages_[loose]};
            f(message(ref), ref);
        }
        // The chunk's messages are parsed before any is handed out, so that a chunk that
        // does not decompress, or whose records break off, is told apart from what `f`
        // throws: the messages before the break are kept, the rest of the chunk skipped.
        chunk_messages_.clear();
        try {
            forEachRecord(loadChunk(i), [&](Op op, std::string_view content, std::size_t offset) {
                if (op == Op::Message) {
                    chunk_messages_.emplace_back(parseMessage(content), MessageRef{i, offset});
                }
            });
        } catch (const McapError& e) {
            const std::string where =
                "chunk at byte " + std::to_string(chunks_[i].chunk_start_offset);
            if (std::find_if(skipped_chunks_.begin(), skipped_chunks_.end(),
                             [&](const std::string& s) { return s.rfind(where, 0) == 0; }) ==
                skipped_chunks_.end()) {
                skipped_chunks_.push_back(where + " is corrupt (" + e.what() +
                                          "): the rest of its messages skipped");
            }
        }
        for (const auto& [view, ref] : chunk_messages_) {
            f(view, ref);
        }
    }
    for (; loose < loose_messages_.size(); ++loose) {
        const MessageRef ref{MessageRef::kNoChunk, loose_messages_[loose]};
        f(message(ref), ref);
    }
}

MessageView Reader::message(const MessageRef& ref)
{
    if (ref.chunk == MessageRef::kNoChunk) {
        std::string prefix;
        if (!readAt(ref.offset, kRecordPrefixSize, prefix) ||
            static_cast<Op>(prefix[0]) != Op::Message) {
            throw McapError(path_ + ": no Message record at byte " + std::to_string(ref.offset));
        }
        ByteReader pr(std::string_view(prefix).substr(1), "Message");
        if (!readAt(ref.offset + kRecordPrefixSize, pr.u64(), raw_)) {
            throw McapError(path_ + ": Message record at byte " + std::to_string(ref.offset) +
                            " is cut short");
        }
        return parseMessage(raw_);
    }
    const std::string_view records = loadChunk(ref.chunk);
    ByteReader r(records.substr(std::min<std::size_t>(ref.offset, records.size())), "Message");
    if (static_cast<Op>(r.u8()) != Op::Message) {
        throw McapError(path_ + ": no Message record at offset " + std::to_string(ref.offset) +
                        " of chunk " + std::to_string(ref.chunk));
    }
    const uint64_t length = r.u64();
    return parseMessage(r.bytes(length));
}

} // namespace stereod::mcap
