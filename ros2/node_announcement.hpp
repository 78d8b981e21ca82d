#pragma once
// Makes a DDS participant known as a ROS 2 node: one rmw_dds_common/msg/ParticipantEntitiesInfo
// on the graph topic `ros_discovery_info`, as rmw_cyclonedds publishes it, so that
// `ros2 node list` shows the node and `ros2 node info` its publishers. The sample names the
// participant's GID and one node (namespace, name) with the GIDs of its readers and
// writers; a GID is the entity's DDS GUID (16 bytes: the participant's 12-byte prefix, then
// the entity id).
//
// QoS as rmw's: reliable, keep last 1, transient local, so that a ROS 2 tool started later
// still gets it.
//
// Thread contract: thread-compatible, used on the thread that makes the participant's
// entities. Ownership: the writer belongs to the participant and goes with it.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "ros2/dds_participant.hpp"

namespace stereod::ros2 {

// The DDS topic of the ROS 2 graph (rmw_dds_common's name).
inline constexpr const char* kDiscoveryInfoTopic = "ros_discovery_info";

// An entity's GID: its DDS GUID. Throws std::runtime_error when Cyclone has none for it.
std::array<uint8_t, 16> entityGid(dds_entity_t entity);

// One node of a participant, as `ros2 node list` shows it: `ns` + "/" + `name`.
struct NodeEntities {
    std::string ns = "/"; // a ROS 2 namespace
    std::string name;
    std::vector<dds_entity_t> readers;
    std::vector<dds_entity_t> writers;
};

// Makes the `ros_discovery_info` writer on `participant` and writes `node` once. Throws
// std::runtime_error with Cyclone's reason.
void announceNode(DdsParticipant& participant, const NodeEntities& node);

} // namespace stereod::ros2
