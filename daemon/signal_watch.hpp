#pragma once
// The one consumer of the service's signals (SIGTERM, SIGINT, SIGHUP), for the whole life
// of the process, including the moments the event loop cannot take them: start-up
// reading a configuration, a calibration or a recording whose open blocks (a FIFO nobody
// writes, a device, a hung mount), or a camera source blocked in its start.
//
// The signals are blocked in every thread (blockServiceSignals(), from .preinit_array
// on) and taken here with sigtimedwait(); no code runs in a signal handler and nothing
// else takes them. SIGTERM and SIGINT go to the service as Service::requestStop(); when
// the event loop has not taken the request within kHandOverMs (there is no service yet,
// or run() has not reached its loop), the process ends through abandonProcess(): the
// socket file the service bound is removed, the log says so, exit code 0. SIGHUP goes to
// the service as Service::requestReload(); before there is a service it is logged and
// dropped (nothing is loaded yet that could be reloaded).
//
// Thread contract: construction, setService() and destruction on the main thread.

#include <atomic>
#include <cstdint>
#include <mutex>
#include <thread>

namespace stereod {

class Service;

class SignalWatch {
  public:
    // How long the event loop has to take a stop request before the process ends without it.
    static constexpr int64_t kHandOverMs = 250;

    SignalWatch();
    ~SignalWatch(); // ends the thread; a signal not taken yet stays pending
    SignalWatch(const SignalWatch&) = delete;
    SignalWatch& operator=(const SignalWatch&) = delete;

    // The service the signals go to; nullptr before it exists and before it is destroyed.
    void setService(Service* service);

  private:
    void run();
    void stop(int signal_number);
    void reload();

    std::thread thread_;
    std::atomic<bool> quit_{false};
    std::mutex mutex_;
    Service* service_ = nullptr; // guarded by mutex_
};

// Blocks SIGTERM, SIGINT and SIGHUP in the calling thread (and the threads it creates
// later), so that they reach the process only through the SignalWatch. Call it first
// thing in main(), before any thread exists.
void blockServiceSignals();

// Ends the process at once with `exit_code`, without the destructors (which would wait
// for threads that cannot stop in time): removes the socket file the service bound,
// flushes the log and the C streams. The one place the process is abandoned, by the
// signal watch during start-up and by main() when the service left its worker running
// (Service::workerAbandoned()). Nothing is lost: the service keeps no state on disk.
[[noreturn]] void abandonProcess(int exit_code) noexcept;

} // namespace stereod
