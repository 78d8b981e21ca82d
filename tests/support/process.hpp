#pragma once
// Child processes for the tests of `stereoctl` and `stereod`: run a command to completion
// and capture what it prints, or start one in the background, read its output line by
// line and signal it. Plus a temporary directory that removes itself.
//
// Thread-bound: each object belongs to the thread that made it. runProcess() is reentrant.

#include <chrono>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include <sys/types.h>

namespace stereod::test {

struct ProcessResult {
    int exit_code = -1; // -1 when the process did not exit normally
    int signal = 0;     // the signal that ended it, if one did
    std::string out;    // everything written to stdout
    std::string err;    // everything written to stderr
};

// Runs `argv` (argv[0] a path) with the environment of this process plus `extra_env`
// ("NAME=value"; a name given here replaces the inherited one), and waits for it.
ProcessResult runProcess(const std::vector<std::string>& argv,
                         const std::vector<std::string>& extra_env = {});

// Number of newline-terminated lines in `text` ("one-line message" checks).
std::size_t lineCount(const std::string& text);

// A process running in the background. Its stdout is a pipe read with readLine();
// its stderr goes to `log_path` (appended) so that a chatty child never blocks on a full
// pipe. Killed with SIGKILL and reaped on destruction if still running.
class ChildProcess {
  public:
    ChildProcess(const std::vector<std::string>& argv, const std::string& log_path);
    ~ChildProcess();
    ChildProcess(const ChildProcess&) = delete;
    ChildProcess& operator=(const ChildProcess&) = delete;

    pid_t pid() const noexcept { return pid_; }

    // The next line of stdout (without the newline), or nullopt when stdout closed or
    // `limit` passed first.
    std::optional<std::string> readLine(std::chrono::milliseconds limit);

    void sendSignal(int signal_number);

    // Waits up to `limit` for the process to end; the wait status, or nullopt if it is
    // still running.
    std::optional<int> waitFor(std::chrono::milliseconds limit);

    bool running();

  private:
    pid_t pid_ = -1;
    int stdout_fd_ = -1;
    std::string buffer_;
    std::optional<int> status_;
};

// The built binaries under test.
std::string stereoctlPath();
std::string stereodPath();

} // namespace stereod::test
