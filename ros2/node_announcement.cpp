#include "ros2/node_announcement.hpp"

#include <cstring>
#include <stdexcept>

#include "ros2_dds_types.h"

namespace stereod::ros2 {

namespace {

std::vector<rmw_dds_common_msg_dds__Gid_> gids(const std::vector<dds_entity_t>& entities)
{
    std::vector<rmw_dds_common_msg_dds__Gid_> out(entities.size());
    for (std::size_t i = 0; i < entities.size(); ++i) {
        const std::array<uint8_t, 16> gid = entityGid(entities[i]);
        std::memcpy(out[i].data, gid.data(), gid.size());
    }
    return out;
}

// Into a bounded IDL string (string<256>: 256 characters and the NUL).
template <std::size_t N> void copyBounded(const std::string& text, char (&out)[N], const char* what)
{
    if (text.size() >= N)
        throw std::runtime_error(std::string(what) + " '" + text + "' is longer than " +
                                 std::to_string(N - 1) + " characters");
    std::memcpy(out, text.c_str(), text.size() + 1);
}

} // namespace

std::array<uint8_t, 16> entityGid(dds_entity_t entity)
{
    dds_guid_t guid{};
    const dds_return_t rc = dds_get_guid(entity, &guid);
    if (rc != DDS_RETCODE_OK)
        throw std::runtime_error(std::string("DDS GUID of an entity: ") + dds_strretcode(rc));
    static_assert(sizeof guid.v == 16);
    std::array<uint8_t, 16> out{};
    std::memcpy(out.data(), guid.v, out.size());
    return out;
}

void announceNode(DdsParticipant& participant, const NodeEntities& node)
{
    const dds_entity_t writer = participant.makeWriter(
        kDiscoveryInfoTopic, rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc,
        QosProfile::StaticTf);

    std::vector<rmw_dds_common_msg_dds__Gid_> readers = gids(node.readers);
    std::vector<rmw_dds_common_msg_dds__Gid_> writers = gids(node.writers);
    rmw_dds_common_msg_dds__NodeEntitiesInfo_ info{};
    copyBounded(node.ns, info.node_namespace, "node namespace");
    copyBounded(node.name, info.node_name, "node name");
    info.reader_gid_seq._buffer = readers.data();
    info.reader_gid_seq._length = info.reader_gid_seq._maximum =
        static_cast<uint32_t>(readers.size());
    info.writer_gid_seq._buffer = writers.data();
    info.writer_gid_seq._length = info.writer_gid_seq._maximum =
        static_cast<uint32_t>(writers.size());

    rmw_dds_common_msg_dds__ParticipantEntitiesInfo_ sample{};
    const std::array<uint8_t, 16> gid = entityGid(participant.handle());
    std::memcpy(sample.gid.data, gid.data(), gid.size());
    sample.node_entities_info_seq._buffer = &info;
    sample.node_entities_info_seq._length = sample.node_entities_info_seq._maximum = 1;

    const dds_return_t rc = dds_write(writer, &sample);
    if (rc != DDS_RETCODE_OK)
        throw std::runtime_error(std::string("DDS write on ") + kDiscoveryInfoTopic + ": " +
                                 dds_strretcode(rc));
}

} // namespace stereod::ros2
