#include "daemon/signal_watch.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>

#include <pthread.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <time.h>

#include "daemon/listening_socket.hpp"
#include "daemon/service.hpp"

namespace stereod {

namespace {

sigset_t serviceSignals()
{
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGTERM);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGHUP);
    return signals;
}

} // namespace

void blockServiceSignals()
{
    const sigset_t signals = serviceSignals();
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);
}

SignalWatch::SignalWatch()
{
    thread_ = std::thread([this] { run(); });
}

SignalWatch::~SignalWatch()
{
    quit_.store(true, std::memory_order_release);
    if (thread_.joinable())
        thread_.join();
}

void SignalWatch::setService(Service* service)
{
    std::lock_guard lock(mutex_);
    service_ = service;
}

void SignalWatch::run()
{
    const sigset_t signals = serviceSignals();
    // Short waits, so that the destructor does not wait long for the thread.
    const timespec step{0, 50'000'000};
    while (!quit_.load(std::memory_order_acquire)) {
        const int signal_number = ::sigtimedwait(&signals, nullptr, &step);
        if (signal_number == SIGHUP)
            reload();
        else if (signal_number > 0)
            stop(signal_number);
    }
}

void SignalWatch::reload()
{
    std::lock_guard lock(mutex_);
    if (service_ != nullptr)
        service_->requestReload();
    else
        spdlog::info("SIGHUP during start-up: nothing to reload yet");
}

void SignalWatch::stop(int signal_number)
{
    const char* name = signal_number == SIGINT ? "SIGINT" : "SIGTERM";
    {
        std::lock_guard lock(mutex_);
        if (service_ != nullptr) {
            spdlog::info("{}: stopping", name);
            service_->requestStop();
            // The event loop took it: the ordinary stop, with its own deadline.
            if (service_->waitStopTaken(kHandOverMs))
                return;
        }
    }
    spdlog::info("{} during start-up: stopping at once", name);
    abandonProcess(0);
}

void abandonProcess(int exit_code) noexcept
{
    removeOwnedSocketFile();
    spdlog::default_logger()->flush();
    std::fflush(nullptr);
    std::_Exit(exit_code);
}

} // namespace stereod
