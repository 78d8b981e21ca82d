#include "tests/support/bags.hpp"

#include <algorithm>
#include <fstream>

#include "replay/mcap_records.hpp"
#include "ros2/messages.hpp"

namespace stereod::test {

ImageMessage monoMessage(const cv::Mat& image, int64_t stamp_ns)
{
    const cv::Mat packed = image.isContinuous() ? image : image.clone();
    ImageMessage m;
    m.stamp_ns = stamp_ns;
    m.height = static_cast<uint32_t>(packed.rows);
    m.width = static_cast<uint32_t>(packed.cols);
    m.encoding = "mono8";
    m.step = static_cast<uint32_t>(packed.cols);
    m.data.assign(reinterpret_cast<const char*>(packed.data), packed.total());
    return m;
}

void writeBag(const std::string& path, const std::vector<BagTopic>& topics,
              mcap::WriterOptions options)
{
    if (options.profile.empty())
        options.profile = "ros2";
    mcap::Writer writer(path, options);
    std::vector<uint16_t> channels;
    for (const BagTopic& t : topics) {
        const uint16_t schema = writer.addSchema(t.schema_name, "ros2msg", ros2::imageSchemaText());
        channels.push_back(writer.addChannel(schema, t.topic, t.message_encoding));
    }
    std::size_t most = 0;
    for (const BagTopic& t : topics)
        most = std::max(most, t.images.size());
    std::string message;
    for (std::size_t k = 0; k < most; ++k) {
        for (std::size_t c = 0; c < topics.size(); ++c) {
            if (k >= topics[c].images.size())
                continue;
            const ImageMessage& m = topics[c].images[k];
            ros2::serializeImage({ros2::Time::fromNs(m.stamp_ns), "camera"}, m.height, m.width,
                                 m.encoding, m.step, m.data.data(), m.data.size(), message);
            const auto t = static_cast<uint64_t>(m.stamp_ns);
            writer.write(channels[c], t, t, message, static_cast<uint32_t>(k));
        }
    }
    writer.close();
}

void writeStereoBag(const std::string& path,
                    const std::vector<std::pair<ImageMessage, ImageMessage>>& pairs,
                    mcap::WriterOptions options)
{
    BagTopic left;
    left.topic = "/stereo/left/image_raw";
    BagTopic right;
    right.topic = "/stereo/right/image_raw";
    for (const auto& [l, r] : pairs) {
        left.images.push_back(l);
        right.images.push_back(r);
    }
    writeBag(path, {left, right}, std::move(options));
}

std::string chunkBag(std::string_view records, uint64_t uncompressed_size,
                     const std::string& compression)
{
    std::string bytes(reinterpret_cast<const char*>(mcap::kMagic), mcap::kMagicSize);
    mcap::ByteWriter w(bytes);
    mcap::writeHeader(w, {"ros2", "stereod tests"});
    mcap::writeSchema(w, {1, "sensor_msgs/msg/Image", "ros2msg", ros2::imageSchemaText()});
    mcap::writeChannel(w, {1, 1, "/stereo/left/image_raw", "cdr", {}});
    const auto chunk = w.beginRecord(mcap::Op::Chunk);
    w.u64(0); // message start and end times
    w.u64(0);
    w.u64(uncompressed_size);
    w.u32(0); // no CRC
    w.str(compression);
    w.u64(records.size());
    w.bytes(records);
    w.endRecord(chunk);
    const auto end = w.beginRecord(mcap::Op::DataEnd);
    w.u32(0);
    w.endRecord(end);
    return bytes;
}

std::string lyingZstdFrame(uint64_t content_size)
{
    std::string frame("\x28\xB5\x2F\xFD", 4); // magic
    frame.push_back(static_cast<char>(0xE0)); // 8-byte content size, single segment
    for (int i = 0; i < 8; ++i)
        frame.push_back(static_cast<char>((content_size >> (8 * i)) & 0xFF));
    frame.append("\x01\x00\x00", 3); // the last block: raw, 0 bytes
    return frame;
}

} // namespace stereod::test
