#pragma once
// SIGTERM and SIGINT at any moment of the process's life, including the moments the
// event loop cannot take them: start-up reading a configuration, a calibration or a
// recording whose open blocks (a FIFO nobody writes, a device, a hung mount), or a
// camera source blocked in its start.
//
// A thread takes the two signals (blocked in every thread, blockServiceSignals()) and
// hands each to the service through Service::requestStop(). When the event loop does not
// pick the request up within kHandOverMs (there is no service yet, or run() has not
// reached its loop), the process cannot stop the ordinary way: the thread removes the
// socket file the service bound (removeOwnedSocketFile()), says so in the log and ends
// the process at once with exit code 0. Nothing is lost: the service keeps no state on
// disk.
//
// Thread contract: construction, setService() and destruction on the main thread.

#include <atomic>
#include <cstdint>
#include <mutex>
#include <thread>

namespace stereod {

class Service;

class StopSignalWatch {
  public:
    // How long the event loop has to take a stop request before the process ends without it.
    static constexpr int64_t kHandOverMs = 250;

    StopSignalWatch();
    ~StopSignalWatch(); // ends the thread; a signal not taken yet stays pending
    StopSignalWatch(const StopSignalWatch&) = delete;
    StopSignalWatch& operator=(const StopSignalWatch&) = delete;

    // The service a signal stops; nullptr before it exists and before it is destroyed.
    void setService(Service* service);

  private:
    void run();
    void stop(int signal_number);

    std::thread thread_;
    std::atomic<bool> quit_{false};
    std::mutex mutex_;
    Service* service_ = nullptr; // guarded by mutex_
};

} // namespace stereod
