#include "ctl/signal_catcher.hpp"

#include <cerrno>
#include <stdexcept>
#include <system_error>

#include <poll.h>
#include <pthread.h>
#include <sys/signalfd.h>
#include <unistd.h>

#include "base/system_error.hpp"

namespace stereod {

SignalCatcher::SignalCatcher()
{
    sigemptyset(&signals_);
    sigaddset(&signals_, SIGINT);
    sigaddset(&signals_, SIGTERM);
    if (pthread_sigmask(SIG_BLOCK, &signals_, &previous_) != 0) {
        throw std::runtime_error("cannot block SIGINT and SIGTERM");
    }
    fd_.reset(::signalfd(-1, &signals_, SFD_CLOEXEC | SFD_NONBLOCK));
    if (!fd_) {
        const int error_number = errno;
        pthread_sigmask(SIG_SETMASK, &previous_, nullptr);
        throw std::runtime_error("cannot create a signalfd: " + errnoText(error_number));
    }
}

SignalCatcher::~SignalCatcher()
{
    // A signal that arrived is consumed first, so that unblocking does not deliver it
    // again and kill the process after it chose to end cleanly.
    signalfd_siginfo info{};
    while (::read(fd_.get(), &info, sizeof(info)) == static_cast<ssize_t>(sizeof(info))) {
    }
    fd_.reset();
    pthread_sigmask(SIG_SETMASK, &previous_, nullptr);
}

bool SignalCatcher::pending() const
{
    pollfd p = {fd_.get(), POLLIN, 0};
    return ::poll(&p, 1, 0) > 0;
}

} // namespace stereod
