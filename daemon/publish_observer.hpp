#pragma once
// Who else watches the results the socket server hands out (the live view), called on
// the socket server's I/O thread. An observer must return quickly and never block: it
// copies what it needs and does its work on its own thread.

#include <cstdint>
#include <string_view>
#include <vector>

#include "daemon/publisher.hpp"

namespace stereod {

class PublishObserver {
  public:
    virtual ~PublishObserver() = default;
    // A new result, and its reading as the protocol's reading object.
    virtual void onFrame(const PublishedFrame& frame, std::string_view reading_json) = 0;
    // Once a second: the `status` object, and the current reading (which may say that
    // no frame comes any more) with the stamp of the pair behind it on CLOCK_REALTIME
    // (PublishedFrame::realtimeNs(); 0: none).
    virtual void onStatus(std::string_view status_json, std::string_view reading_json,
                          int64_t reading_realtime_ns) = 0;
};

// Several observers as one (the live view and the ROS 2 node), each called in turn.
// Borrows them; they must outlive it. Set up before the socket server runs.
class PublishObservers final : public PublishObserver {
  public:
    void add(PublishObserver& observer) { observers_.push_back(&observer); }
    bool empty() const noexcept { return observers_.empty(); }

    void onFrame(const PublishedFrame& frame, std::string_view reading_json) override
    {
        for (PublishObserver* observer : observers_)
            observer->onFrame(frame, reading_json);
    }
    void onStatus(std::string_view status_json, std::string_view reading_json,
                  int64_t reading_stamp_ns) override
    {
        for (PublishObserver* observer : observers_)
            observer->onStatus(status_json, reading_json, reading_stamp_ns);
    }

  private:
    std::vector<PublishObserver*> observers_;
};

} // namespace stereod
