#pragma once
// The ROS 2 node's feed: the results the socket server hands out, passed on to the ROS 2
// publisher (ros2/ros2_publisher.hpp), as the live view gets them. Called on the socket
// server's I/O thread; the publisher copies what its readers want and returns.
//
// Ownership: borrows the publisher, which must outlive it.

#include <cstdint>
#include <string_view>

#include "daemon/publish_observer.hpp"
#include "ros2/ros2_publisher.hpp"

namespace stereod {

class Ros2Observer final : public PublishObserver {
  public:
    explicit Ros2Observer(ros2::Ros2Publisher& publisher) : publisher_(publisher) {}

    void onFrame(const PublishedFrame& frame, std::string_view reading_json) override
    {
        publisher_.offerFrame(frame.result, frame.realtimeNs(frame.result.stamp_ns),
                              frame.depth_valid, frame.stats.range, frame.camera_pose,
                              reading_json);
    }
    void onStatus(std::string_view /*status_json*/, std::string_view reading_json,
                  int64_t reading_realtime_ns) override
    {
        publisher_.offerStatus(reading_json, reading_realtime_ns);
    }

  private:
    ros2::Ros2Publisher& publisher_;
};

} // namespace stereod
