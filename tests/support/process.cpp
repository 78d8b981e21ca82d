#include "tests/support/process.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <system_error>
#include <thread>
#include <utility>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace stereod::test {

namespace {

[[noreturn]] void throwErrno(const std::string& what)
{
    throw std::system_error(errno, std::system_category(), what);
}

// argv/envp arrays for posix_spawn, pointing into `strings`.
std::vector<char*> pointers(std::vector<std::string>& strings)
{
    std::vector<char*> out;
    out.reserve(strings.size() + 1);
    for (std::string& s : strings) {
        out.push_back(s.data());
    }
    out.push_back(nullptr);
    return out;
}

std::vector<std::string> environment(const std::vector<std::string>& extra)
{
    std::vector<std::string> env;
    const auto overridden = [&](const char* entry) {
        for (const std::string& e : extra) {
            const std::size_t name_length = e.find('=');
            if (std::strncmp(entry, e.c_str(), name_length + 1) == 0) {
                return true;
            }
        }
        return false;
    };
    for (char** e = environ; *e != nullptr; ++e) {
        if (!overridden(*e)) {
            env.emplace_back(*e);
        }
    }
    env.insert(env.end(), extra.begin(), extra.end());
    return env;
}

struct Pipe {
    int read_fd = -1;
    int write_fd = -1;
    Pipe()
    {
        int fds[2];
        if (::pipe2(fds, O_CLOEXEC) != 0) {
            throwErrno("pipe2");
        }
        read_fd = fds[0];
        write_fd = fds[1];
    }
    ~Pipe()
    {
        closeRead();
        closeWrite();
    }
    void closeRead()
    {
        if (read_fd >= 0) {
            ::close(read_fd);
            read_fd = -1;
        }
    }
    void closeWrite()
    {
        if (write_fd >= 0) {
            ::close(write_fd);
            write_fd = -1;
        }
    }
};

// Starts `argv` with stdout and stderr redirected as the file actions say.
pid_t spawn(const std::vector<std::string>& argv, const std::vector<std::string>& extra_env,
            posix_spawn_file_actions_t* actions)
{
    std::vector<std::string> args = argv;
    std::vector<std::string> env = environment(extra_env);
    std::vector<char*> arg_pointers = pointers(args);
    std::vector<char*> env_pointers = pointers(env);
    pid_t pid = -1;
    const int error = ::posix_spawn(&pid, args.at(0).c_str(), actions, nullptr, arg_pointers.data(),
                                    env_pointers.data());
    if (error != 0) {
        throw std::system_error(error, std::system_category(), "posix_spawn " + argv.at(0));
    }
    return pid;
}

} // namespace

ProcessResult runProcess(const std::vector<std::string>& argv,
                         const std::vector<std::string>& extra_env)
{
    Pipe out;
    Pipe err;
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, out.write_fd, STDOUT_FILENO);
    posix_spawn_file_actions_adddup2(&actions, err.write_fd, STDERR_FILENO);
    pid_t pid = -1;
    try {
        pid = spawn(argv, extra_env, &actions);
    } catch (...) {
        posix_spawn_file_actions_destroy(&actions);
        throw;
    }
    posix_spawn_file_actions_destroy(&actions);
    out.closeWrite();
    err.closeWrite();

    ProcessResult result;
    pollfd fds[2] = {{out.read_fd, POLLIN, 0}, {err.read_fd, POLLIN, 0}};
    std::string* sinks[2] = {&result.out, &result.err};
    int open_count = 2;
    while (open_count > 0) {
        if (::poll(fds, 2, -1) < 0) {
            if (errno == EINTR) {
                continue;
            }
            throwErrno("poll");
        }
        for (int i = 0; i < 2; ++i) {
            if (fds[i].fd < 0 || fds[i].revents == 0) {
                continue;
            }
            char buffer[4096];
            const ssize_t n = ::read(fds[i].fd, buffer, sizeof(buffer));
            if (n > 0) {
                sinks[i]->append(buffer, static_cast<std::size_t>(n));
            } else if (n == 0 || errno != EINTR) {
                fds[i].fd = -1;
                --open_count;
            }
        }
    }
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0) {
        if (errno != EINTR) {
            throwErrno("waitpid");
        }
    }
    if (WIFEXITED(status)) {
        result.exit_code = WEXITSTATUS(status);
    } else if (WIFSIGNALED(status)) {
        result.signal = WTERMSIG(status);
    }
    return result;
}

std::size_t lineCount(const std::string& text)
{
    return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

ChildProcess::ChildProcess(const std::vector<std::string>& argv, const std::string& log_path)
{
    Pipe out;
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, out.write_fd, STDOUT_FILENO);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, log_path.c_str(),
                                     O_WRONLY | O_CREAT | O_APPEND, 0644);
    try {
        pid_ = spawn(argv, {}, &actions);
    } catch (...) {
        posix_spawn_file_actions_destroy(&actions);
        throw;
    }
    posix_spawn_file_actions_destroy(&actions);
    out.closeWrite();
    stdout_fd_ = std::exchange(out.read_fd, -1);
}

ChildProcess::~ChildProcess()
{
    if (running()) {
        ::kill(pid_, SIGKILL);
        waitFor(std::chrono::milliseconds(-1));
    }
    if (stdout_fd_ >= 0) {
        ::close(stdout_fd_);
    }
}

std::optional<std::string> ChildProcess::readLine(std::chrono::milliseconds limit)
{
    const auto deadline = std::chrono::steady_clock::now() + limit;
    for (;;) {
        if (const std::size_t newline = buffer_.find('\n'); newline != std::string::npos) {
            std::string line = buffer_.substr(0, newline);
            buffer_.erase(0, newline + 1);
            return line;
        }
        if (stdout_fd_ < 0) {
            return std::nullopt;
        }
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
            deadline - std::chrono::steady_clock::now());
        if (left.count() <= 0) {
            return std::nullopt;
        }
        pollfd fd = {stdout_fd_, POLLIN, 0};
        const int ready = ::poll(&fd, 1, static_cast<int>(left.count()));
        if (ready < 0 && errno != EINTR) {
            throwErrno("poll");
        }
        if (ready <= 0) {
            continue;
        }
        char buffer[4096];
        const ssize_t n = ::read(stdout_fd_, buffer, sizeof(buffer));
        if (n > 0) {
            buffer_.append(buffer, static_cast<std::size_t>(n));
        } else if (n == 0 || errno != EINTR) {
            ::close(stdout_fd_);
            stdout_fd_ = -1;
        }
    }
}

void ChildProcess::sendSignal(int signal_number)
{
    if (running() && ::kill(pid_, signal_number) != 0) {
        throwErrno("kill " + std::to_string(pid_));
    }
}

std::optional<int> ChildProcess::waitFor(std::chrono::milliseconds limit)
{
    if (status_) {
        return status_;
    }
    const auto deadline = std::chrono::steady_clock::now() + limit;
    for (;;) {
        int status = 0;
        const pid_t done = ::waitpid(pid_, &status, limit.count() < 0 ? 0 : WNOHANG);
        if (done == pid_) {
            status_ = status;
            return status_;
        }
        if (done < 0 && errno != EINTR) {
            throwErrno("waitpid " + std::to_string(pid_));
        }
        if (limit.count() >= 0 && std::chrono::steady_clock::now() >= deadline) {
            return std::nullopt;
        }
        // Polled: SIGCHLD handling would reach into the test framework's signal setup.
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
}

bool ChildProcess::running()
{
    return !waitFor(std::chrono::milliseconds(0)).has_value();
}

std::string stereoctlPath()
{
    return std::string(STEREOD_BINARY_DIR) + "/ctl/stereoctl";
}

std::string stereodPath()
{
    return std::string(STEREOD_BINARY_DIR) + "/daemon/stereod";
}

} // namespace stereod::test
