#pragma once
// SIGINT and SIGTERM taken through a signalfd, so that a command that waits for the service
// (`watch`, `calibrate --live`) can end its wait cleanly instead of being killed.
//
// Thread-bound: changes the calling thread's signal mask while it lives.

#include <signal.h>

#include "base/unique_fd.hpp"

namespace stereod {

// Blocks SIGINT and SIGTERM and takes them through a signalfd instead; restores the mask
// on destruction. Throws std::runtime_error (with the errno text) when it cannot.
class SignalCatcher {
  public:
    SignalCatcher();
    ~SignalCatcher();
    SignalCatcher(const SignalCatcher&) = delete;
    SignalCatcher& operator=(const SignalCatcher&) = delete;

    // Readable when a signal is waiting: for ProtocolClient::setCancelFd.
    int fd() const noexcept { return fd_.get(); }

    // True when a signal is waiting: checked between events, because the client only
    // looks at the descriptor when it has to wait, and a busy stream may never make it.
    bool pending() const;

  private:
    sigset_t signals_{};
    sigset_t previous_{};
    UniqueFd fd_;
};

} // namespace stereod
