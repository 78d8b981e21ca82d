#include "ros2/dds_participant.hpp"

#include <charconv>
#include <cstdlib>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string_view>

namespace stereod::ros2 {

namespace {

// The highest domain id whose UDP ports fit (RTPS: 7400 + 250 * domain + 10 + 2 * index).
constexpr uint32_t kMaxDomainId = 232;

std::string_view environment(const char* name)
{
    const char* value = std::getenv(name);
    return value == nullptr ? std::string_view() : std::string_view(value);
}

std::string ddsError(dds_return_t code)
{
    return dds_strretcode(code);
}

using QosPtr = std::unique_ptr<dds_qos_t, decltype(&dds_delete_qos)>;

QosPtr makeQos(QosProfile profile)
{
    QosPtr qos(dds_create_qos(), &dds_delete_qos);
    switch (profile) {
    case QosProfile::SensorData:
        dds_qset_reliability(qos.get(), DDS_RELIABILITY_BEST_EFFORT, 0);
        dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, 5);
        dds_qset_durability(qos.get(), DDS_DURABILITY_VOLATILE);
        break;
    case QosProfile::Reliable:
        // A reader that does not acknowledge holds a write up to 100 ms (rmw's default),
        // then the oldest unacknowledged sample gives way: keep last bounds it.
        dds_qset_reliability(qos.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
        dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, 10);
        dds_qset_durability(qos.get(), DDS_DURABILITY_VOLATILE);
        break;
    case QosProfile::StaticTf:
        dds_qset_reliability(qos.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
        dds_qset_history(qos.get(), DDS_HISTORY_KEEP_LAST, 1);
        dds_qset_durability(qos.get(), DDS_DURABILITY_TRANSIENT_LOCAL);
        break;
    }
    return qos;
}

} // namespace

// A localhost-only domain entity, deleted when its last participant of this process is.
// Cyclone refuses a second dds_create_domain() of one id, so the publisher and the ROS 2
// source share it.
struct LocalhostDomain {
    dds_entity_t entity = 0;
    ~LocalhostDomain()
    {
        if (entity > 0)
            dds_delete(entity);
    }
};

namespace {

// The localhost-only domain of `domain_id`, made with cycloneLocalhostConfig() by its
// first user. Throws std::runtime_error with Cyclone's reason.
std::shared_ptr<LocalhostDomain> sharedLocalhostDomain(uint32_t domain_id)
{
    static std::mutex mutex;
    static std::map<uint32_t, std::weak_ptr<LocalhostDomain>> domains; // guarded by mutex
    const std::lock_guard lock(mutex);
    if (std::shared_ptr<LocalhostDomain> existing = domains[domain_id].lock())
        return existing;
    auto domain = std::make_shared<LocalhostDomain>();
    domain->entity = dds_create_domain(domain_id, cycloneLocalhostConfig(domain_id).c_str());
    if (domain->entity < 0) {
        const dds_return_t code = domain->entity;
        domain->entity = 0;
        throw std::runtime_error("DDS domain " + std::to_string(domain_id) +
                                 " on 127.0.0.1: " + ddsError(code));
    }
    domains[domain_id] = domain;
    return domain;
}

} // namespace

DdsDiscovery discoveryFromEnvironment(bool config_localhost_only)
{
    DdsDiscovery discovery;
    const std::string_view domain = environment("ROS_DOMAIN_ID");
    if (!domain.empty()) {
        uint32_t id = 0;
        const auto [end, error] = std::from_chars(domain.data(), domain.data() + domain.size(), id);
        if (error != std::errc() || end != domain.data() + domain.size() || id > kMaxDomainId)
            throw std::invalid_argument("ROS_DOMAIN_ID: '" + std::string(domain) +
                                        "' is not a domain id (0 to " +
                                        std::to_string(kMaxDomainId) + ")");
        discovery.domain_id = id;
    }
    discovery.localhost_only = config_localhost_only || environment("ROS_LOCALHOST_ONLY") == "1" ||
                               environment("ROS_AUTOMATIC_DISCOVERY_RANGE") == "LOCALHOST";
    return discovery;
}

std::string cycloneLocalhostConfig(uint32_t domain_id)
{
    // Peers are probed on localhost at the ports of participant indices 0 to
    // MaxAutoParticipantIndex: that many DDS participants on the machine find each other.
    return "<CycloneDDS><Domain Id=\"" + std::to_string(domain_id) +
           "\"><General><Interfaces><NetworkInterface address=\"127.0.0.1\"/></Interfaces>"
           "<AllowMulticast>false</AllowMulticast>"
           "<MaxMessageSize>65000B</MaxMessageSize><FragmentSize>64000B</FragmentSize>"
           "</General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
           "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
           "<Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery></Domain></CycloneDDS>";
}

DdsParticipant::DdsParticipant(const DdsDiscovery& discovery)
{
    if (discovery.localhost_only)
        domain_ = sharedLocalhostDomain(discovery.domain_id);
    participant_ = dds_create_participant(discovery.domain_id, nullptr, nullptr);
    if (participant_ < 0) {
        const dds_return_t code = participant_;
        participant_ = 0;
        throw std::runtime_error("DDS participant in domain " +
                                 std::to_string(discovery.domain_id) + ": " + ddsError(code));
    }
}

DdsParticipant::~DdsParticipant()
{
    if (participant_ > 0)
        dds_delete(participant_);
}

dds_entity_t DdsParticipant::makeTopic(const std::string& dds_topic,
                                       const dds_topic_descriptor_t& descriptor,
                                       const dds_qos_t* qos)
{
    // One topic entity per name and participant: a second dds_create_topic() of the same
    // name and type gives the same topic.
    const dds_entity_t topic =
        dds_create_topic(participant_, &descriptor, dds_topic.c_str(), qos, nullptr);
    if (topic < 0)
        throw std::runtime_error("DDS topic " + dds_topic + ": " + ddsError(topic));
    return topic;
}

dds_entity_t DdsParticipant::makeWriter(const std::string& dds_topic,
                                        const dds_topic_descriptor_t& descriptor,
                                        QosProfile profile)
{
    const QosPtr qos = makeQos(profile);
    const dds_entity_t topic = makeTopic(dds_topic, descriptor, qos.get());
    const dds_entity_t writer = dds_create_writer(participant_, topic, qos.get(), nullptr);
    if (writer < 0)
        throw std::runtime_error("DDS writer on " + dds_topic + ": " + ddsError(writer));
    return writer;
}

dds_entity_t DdsParticipant::makeReader(const std::string& dds_topic,
                                        const dds_topic_descriptor_t& descriptor,
                                        QosProfile profile)
{
    const QosPtr qos = makeQos(profile);
    const dds_entity_t topic = makeTopic(dds_topic, descriptor, qos.get());
    const dds_entity_t reader = dds_create_reader(participant_, topic, qos.get(), nullptr);
    if (reader < 0)
        throw std::runtime_error("DDS reader on " + dds_topic + ": " + ddsError(reader));
    return reader;
}

uint32_t DdsParticipant::matchedWriters(dds_entity_t reader) noexcept
{
    dds_subscription_matched_status_t status{};
    if (dds_get_subscription_matched_status(reader, &status) != DDS_RETCODE_OK)
        return 0;
    return status.current_count;
}

uint32_t DdsParticipant::matchedReaders(dds_entity_t writer) noexcept
{
    dds_publication_matched_status_t status{};
    if (dds_get_publication_matched_status(writer, &status) != DDS_RETCODE_OK)
        return 0;
    return status.current_count;
}

} // namespace stereod::ros2
