// health_replay: the calibration health monitor (daemon/calibration_health_monitor.hpp) fed
// a rig's raw pairs, rectified with its calibration, in a loop and back to back: what the
// service's checks would say over `--checks` checks (one every 2 s in the service, so 300
// are ten minutes). Prints the state changes, how many checks left the state degraded or
// failed (readings made then are flagged), what each check cost and how the process's
// resident memory grew.
//
//   health_replay --calib demo/chessboard/calibration.yaml --checks 300
//                 LEFT01 RIGHT01 LEFT02 RIGHT02 ...

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <sys/resource.h>
#include <unistd.h>

#include "capture/frame.hpp"
#include "daemon/calibration_health_monitor.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/rectifier.hpp"

namespace {

double residentMb()
{
    std::ifstream statm("/proc/self/statm");
    long pages = 0, resident = 0;
    statm >> pages >> resident;
    return static_cast<double>(resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / 1e6;
}

// CPU time of the whole process, ms: on a loaded machine a check's wall time says more
// about the other processes than about the check.
double cpuMs()
{
    rusage usage{};
    ::getrusage(RUSAGE_SELF, &usage);
    return (static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) * 1e3) +
           static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) / 1e3;
}

int usage()
{
    std::fprintf(stderr, "usage: health_replay --calib FILE [--checks N] [--verbose] LEFT RIGHT "
                         "[LEFT RIGHT ...]\n");
    return 2;
}

} // namespace

int main(int argc, char** argv)
{
    using namespace stereod;
    std::string calib_path;
    int checks = 300;
    bool verbose = false;
    std::vector<std::string> files;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg == "--calib" && i + 1 < argc)
            calib_path = argv[++i];
        else if (arg == "--checks" && i + 1 < argc)
            checks = std::atoi(argv[++i]);
        else if (arg == "--verbose")
            verbose = true;
        else
            files.push_back(arg);
    }
    if (calib_path.empty() || files.empty() || files.size() % 2 != 0 || checks <= 0)
        return usage();

    const StereoCalibration calibration = loadCalibration(calib_path);
    const Rectifier rectifier(calibration);
    struct Pair {
        cv::Mat left, right;
    };
    std::vector<Pair> pairs;
    for (size_t i = 0; i < files.size(); i += 2) {
        const cv::Mat left = cv::imread(files[i], cv::IMREAD_GRAYSCALE);
        const cv::Mat right = cv::imread(files[i + 1], cv::IMREAD_GRAYSCALE);
        if (left.empty() || right.empty()) {
            std::fprintf(stderr, "health_replay: cannot read %s or %s\n", files[i].c_str(),
                         files[i + 1].c_str());
            return 2;
        }
        Pair pair;
        rectifier.rectifyLeft(left, pair.left);
        rectifier.rectifyRight(right, pair.right);
        pairs.push_back(pair);
    }

    // The shortest interval: a check is due as soon as the previous one is done.
    CalibrationHealthMonitor monitor(calibration.rectified, 1e-9);
    HealthState previous = HealthState::Unknown;
    int changes = 0, alarms = 0, flagged = 0;
    std::vector<double> check_ms;
    const double rss_start = residentMb();
    const double cpu_start = cpuMs();
    double rss_after_first = 0.0;
    for (int i = 0; i < checks; ++i) {
        const Pair& pair = pairs[static_cast<size_t>(i) % pairs.size()];
        while (!monitor.due(monotonicNowNs()))
            std::this_thread::sleep_for(std::chrono::microseconds(200));
        monitor.offer(pair.left, pair.right, monotonicNowNs());
        HealthReport report = monitor.report();
        while (report.checks < static_cast<uint64_t>(i + 1)) {
            std::this_thread::sleep_for(std::chrono::microseconds(200));
            report = monitor.report();
        }
        check_ms.push_back(report.check_ms);
        if (i == 0)
            rss_after_first = residentMb();
        const bool bad =
            report.state == HealthState::Degraded || report.state == HealthState::Failed;
        const bool was_bad = previous == HealthState::Degraded || previous == HealthState::Failed;
        if (report.state != previous && previous != HealthState::Unknown)
            ++changes;
        alarms += bad && !was_bad && previous != HealthState::Unknown;
        previous = report.state;
        flagged += bad;
        if (verbose)
            std::printf(
                "check %3d pair %2zu: %-8s %-18s (this check %-8s) %4d matches, rows up "
                "to %.2f px apart, %+.2f px at the centre, roll %+.3f deg, %.0f ms\n",
                i + 1, static_cast<size_t>(i) % pairs.size() + 1, healthStateName(report.state),
                report.reason.c_str(), healthStateName(report.last_check_state), report.matches,
                report.max_row_error_px, report.offset_px, report.roll_deg, report.check_ms);
    }
    const double rss_end = residentMb();
    const double cpu_per_check = (cpuMs() - cpu_start) / checks;
    std::vector<double> sorted = check_ms;
    std::sort(sorted.begin(), sorted.end());
    std::printf("%d checks of %zu pairs: %d state changes after the first verdict (%d into "
                "degraded or failed), %d checks left the state degraded or failed (%.0f %%), last "
                "state %s\n",
                checks, pairs.size(), changes, alarms, flagged, 100.0 * flagged / checks,
                healthStateName(previous));
    std::printf("check_ms: first %.0f, median %.0f, last %.0f, max %.0f; CPU %.0f ms per check\n",
                check_ms.front(), sorted[sorted.size() / 2], check_ms.back(), sorted.back(),
                cpu_per_check);
    std::printf("resident memory: %.1f MB at the start, %.1f MB after the first check, %.1f MB "
                "at the end (%+.1f KB per check after the first)\n",
                rss_start, rss_after_first, rss_end,
                checks > 1 ? (rss_end - rss_after_first) * 1e3 / (checks - 1) : 0.0);
    return 0;
}
