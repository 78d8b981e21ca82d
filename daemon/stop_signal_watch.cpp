#include "daemon/stop_signal_watch.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>

#include <signal.h>
#include <spdlog/spdlog.h>
#include <time.h>

#include "daemon/listening_socket.hpp"
#include "daemon/service.hpp"

namespace stereod {

StopSignalWatch::StopSignalWatch()
{
    thread_ = std::thread([this] { run(); });
}

StopSignalWatch::~StopSignalWatch()
{
    quit_.store(true, std::memory_order_release);
    if (thread_.joinable())
        thread_.join();
}

void StopSignalWatch::setService(Service* service)
{
    std::lock_guard lock(mutex_);
    service_ = service;
}

void StopSignalWatch::run()
{
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGTERM);
    sigaddset(&signals, SIGINT);
    // Short waits, so that the destructor does not wait long for the thread.
    const timespec step{0, 50'000'000};
    while (!quit_.load(std::memory_order_acquire)) {
        const int signal_number = ::sigtimedwait(&signals, nullptr, &step);
        if (signal_number > 0)
            stop(signal_number);
    }
}

void StopSignalWatch::stop(int signal_number)
{
    const char* name = signal_number == SIGINT ? "SIGINT" : "SIGTERM";
    {
        std::lock_guard lock(mutex_);
        if (service_ != nullptr) {
            spdlog::info("{}: stopping", name);
            service_->requestStop();
            const auto deadline =
                std::chrono::steady_clock::now() + std::chrono::milliseconds(kHandOverMs);
            while (!service_->stopRequested() && std::chrono::steady_clock::now() < deadline)
                std::this_thread::sleep_for(std::chrono::milliseconds(2));
            // The event loop took it: the ordinary stop, with its own deadline.
            if (service_->stopRequested())
                return;
        }
    }
    spdlog::info("{} during start-up: stopping at once", name);
    removeOwnedSocketFile();
    spdlog::default_logger()->flush();
    std::fflush(nullptr);
    std::_Exit(0);
}

} // namespace stereod
