#pragma once
// The Fast DDS test peers' participant settings (tests/ros2/fastdds_subscriber.cpp,
// fastdds_image_publisher.cpp): the loopback interface only, no multicast, and stereod
// found at the well-known ports of the first 33 participant indices on 127.0.0.1, as its
// localhost-only discovery expects.
//
// Reentrant: builds a value.

#include <memory>
#include <string>

#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

namespace stereod::test {

inline eprosima::fastdds::dds::DomainParticipantQos loopbackParticipantQos(const std::string& name)
{
    eprosima::fastdds::dds::DomainParticipantQos qos;
    qos.name(name);
    qos.transport().use_builtin_transports = false;
    auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
    udp->interfaceWhiteList.push_back("127.0.0.1");
    // Images come in many fragments at once.
    udp->receiveBufferSize = 4 * 1024 * 1024;
    udp->sendBufferSize = 4 * 1024 * 1024;
    udp->maxInitialPeersRange = 33;
    qos.transport().user_transports.push_back(udp);
    eprosima::fastrtps::rtps::Locator_t peer;
    peer.kind = LOCATOR_KIND_UDPv4;
    eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, "127.0.0.1");
    qos.wire_protocol().builtin.initialPeersList.push_back(peer);
    return qos;
}

} // namespace stereod::test
