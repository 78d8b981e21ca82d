#pragma once
// One DDS domain participant (Eclipse Cyclone DDS) and the writers and readers made on it,
// with the QoS profiles ROS 2 uses, and where discovery may go: by default the loopback interface
// only (127.0.0.1, no multicast, peers found on localhost), as ROS_LOCALHOST_ONLY=1 and
// ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST ask of a ROS 2 node; widened, Cyclone's own
// configuration (CYCLONEDDS_URI, else its defaults) decides.
//
// Thread contract: thread-compatible; each owner makes it and its entities on one thread
// and then uses them from one (the ROS 2 publisher's writers, the ROS 2 source's readers).
// Several participants of one process may share a domain (the publisher's and the ROS 2
// source's): the localhost-only domain is made by the first and deleted with the last.
// Ownership: owns the participant, and so its topics, writers and readers (dds_entity_t
// handles); shares the domain entity with the process's other participants in it.

#include <cstdint>
#include <memory>
#include <string>

#include <dds/dds.h>

namespace stereod::ros2 {

// Where discovery may go and in which domain.
struct DdsDiscovery {
    uint32_t domain_id = 0; // ROS_DOMAIN_ID, 0..232 (UDP ports are 7400 + 250 * domain + ...)
    bool localhost_only = true;
};

// The discovery asked for by the environment and the configuration: ROS_DOMAIN_ID (unset:
// 0); localhost-only unless `config_localhost_only` is false, and even then when
// ROS_LOCALHOST_ONLY=1 or ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST say so. Throws
// std::invalid_argument naming the variable when ROS_DOMAIN_ID is not a domain.
DdsDiscovery discoveryFromEnvironment(bool config_localhost_only);

// The Cyclone DDS configuration (XML) for `discovery` when localhost-only: the loopback
// interface, multicast off, localhost as the peer, and datagrams up to the loopback's size
// so that an image travels in few fragments.
std::string cycloneLocalhostConfig(uint32_t domain_id);

// The QoS profiles of ROS 2 (rmw's names).
enum class QosProfile {
    SensorData, // best effort, keep last 5, volatile: images, clouds
    Reliable,   // reliable, keep last 10, volatile: the reading, camera_info
    StaticTf,   // reliable, keep last 1, transient local: /tf_static, as tf2's static
                // broadcaster, and ros_discovery_info, as rmw: late joiners get it
};

// A localhost-only domain entity shared by the process's participants in it.
struct LocalhostDomain;

class DdsParticipant {
  public:
    // Creates the domain (localhost-only: with cycloneLocalhostConfig) and the
    // participant. Throws std::runtime_error with Cyclone's reason when it cannot.
    explicit DdsParticipant(const DdsDiscovery& discovery);
    ~DdsParticipant();
    DdsParticipant(const DdsParticipant&) = delete;
    DdsParticipant& operator=(const DdsParticipant&) = delete;

    // A writer of `descriptor`'s type on the DDS topic `dds_topic` ("rt/stereo/depth").
    // Throws std::runtime_error naming the topic when Cyclone refuses.
    dds_entity_t makeWriter(const std::string& dds_topic, const dds_topic_descriptor_t& descriptor,
                            QosProfile profile);

    // A reader of `descriptor`'s type on the DDS topic `dds_topic`, with `profile`'s QoS
    // (a best-effort reader matches reliable writers too). Throws std::runtime_error naming
    // the topic when Cyclone refuses.
    dds_entity_t makeReader(const std::string& dds_topic, const dds_topic_descriptor_t& descriptor,
                            QosProfile profile);

    // The participant entity, for waitsets and guard conditions made on it.
    dds_entity_t handle() const noexcept { return participant_; }

    // How many readers match `writer` now (0 on error).
    static uint32_t matchedReaders(dds_entity_t writer) noexcept;
    // How many writers match `reader` now (0 on error).
    static uint32_t matchedWriters(dds_entity_t reader) noexcept;

  private:
    dds_entity_t makeTopic(const std::string& dds_topic, const dds_topic_descriptor_t& descriptor,
                           const dds_qos_t* qos);

    std::shared_ptr<LocalhostDomain> domain_; // null: none made (widened: the default domain)
    dds_entity_t participant_ = 0;
};

} // namespace stereod::ros2
