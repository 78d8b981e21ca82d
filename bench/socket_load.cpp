// socket_load: the socket server under load, measured against a running stereod.
//
//   socket_load --socket PATH [--clients 256] [--threads 16] [--seconds 10]
//               [--depth-subscribers 4] [--sleepers 1]
//
// Opens --clients connections that ask `distance` in a loop (each of --threads threads
// sends one request on each of its connections, then reads every reply), while depth
// subscribers read every frame and --sleepers subscribe to depth frames and never read.
// Prints one JSON object: requests answered per second, p50/p99/max latency of
// `distance` (send to reply, ms), wrong or failed replies, and the frames the service
// processed meanwhile with its frame rate, so a slowed worker shows. The correctness of
// the same situation is asserted by tests/daemon/reliability_test.cpp.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "ctl/client.hpp"

namespace {

using stereod::ProtocolClient;
using Json = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

constexpr auto kWait = 30000ms;

struct ThreadResult {
    std::vector<double> latencies_ms;
    uint64_t errors = 0;
    std::string first_error;
};

void askDistance(const std::string& socket_path, int connections, const std::atomic<bool>& stop,
                 ThreadResult& result)
{
    try {
        std::vector<ProtocolClient> clients;
        for (int i = 0; i < connections; ++i)
            clients.emplace_back(socket_path, kWait);
        std::vector<Clock::time_point> sent(clients.size());
        const std::string line = "{\"cmd\":\"distance\",\"max_age_ms\":600000}\n";
        while (!stop.load()) {
            for (std::size_t i = 0; i < clients.size(); ++i) {
                sent[i] = Clock::now();
                clients[i].sendRaw(line);
            }
            for (std::size_t i = 0; i < clients.size(); ++i) {
                Json reply = clients[i].readJson();
                const auto took = Clock::now() - sent[i];
                if (reply.value("ok", false) && reply["reading"].value("valid", false)) {
                    result.latencies_ms.push_back(
                        std::chrono::duration<double, std::milli>(took).count());
                } else {
                    if (result.errors++ == 0)
                        result.first_error = reply.dump();
                }
            }
        }
    } catch (const std::exception& e) {
        if (result.errors++ == 0)
            result.first_error = e.what();
    }
}

void readDepth(const std::string& socket_path, const std::atomic<bool>& stop,
               std::atomic<uint64_t>& events)
{
    try {
        ProtocolClient client(socket_path, kWait);
        client.request({{"cmd", "subscribe"}, {"stream", "depth"}});
        while (!stop.load()) {
            Json event = client.readJson();
            client.skipPayload(event.value("bytes", std::size_t{0}));
            ++events;
        }
    } catch (const std::exception& e) {
        std::cerr << "socket_load: depth subscriber: " << e.what() << "\n";
    }
}

uint64_t processedFrames(const std::string& socket_path)
{
    ProtocolClient client(socket_path, kWait);
    return client.request({{"cmd", "status"}})["status"]["pipeline"]["frames"].get<uint64_t>();
}

double percentile(std::vector<double>& values, double p)
{
    if (values.empty())
        return 0.0;
    const auto rank = static_cast<std::size_t>(p / 100.0 * static_cast<double>(values.size() - 1));
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(rank),
                     values.end());
    return values[rank];
}

} // namespace

int main(int argc, char** argv)
{
    CLI::App app("Load on a running stereod's socket: distance requests per second and "
                 "their latency, with depth subscribers and subscribers that never read");
    std::string socket_path;
    int clients = 256;
    int threads = 16;
    double seconds = 10.0;
    int depth_subscribers = 4;
    int sleepers = 1;
    app.add_option("--socket", socket_path, "the service's socket")->required();
    app.add_option("--clients", clients, "connections asking distance")->check(CLI::Range(1, 4096));
    app.add_option("--threads", threads, "client threads")->check(CLI::Range(1, 256));
    app.add_option("--seconds", seconds, "how long to load")->check(CLI::Range(0.1, 3600.0));
    app.add_option("--depth-subscribers", depth_subscribers, "depth subscribers that read")
        ->check(CLI::Range(0, 256));
    app.add_option("--sleepers", sleepers, "depth subscribers that never read")
        ->check(CLI::Range(0, 256));
    CLI11_PARSE(app, argc, argv);
    threads = std::min(threads, clients);

    try {
        std::atomic<bool> stop{false};
        std::atomic<uint64_t> depth_events{0};
        std::vector<ProtocolClient> sleeping;
        for (int i = 0; i < sleepers; ++i) {
            sleeping.emplace_back(socket_path, kWait);
            sleeping.back().sendRequest({{"cmd", "subscribe"}, {"stream", "depth"}});
        }
        std::vector<std::thread> readers;
        for (int i = 0; i < depth_subscribers; ++i)
            readers.emplace_back(readDepth, socket_path, std::cref(stop), std::ref(depth_events));

        const uint64_t frames_before = processedFrames(socket_path);
        std::vector<ThreadResult> results(static_cast<std::size_t>(threads));
        std::vector<std::thread> askers;
        const auto start = Clock::now();
        for (int t = 0; t < threads; ++t) {
            const int mine = clients / threads + (t < clients % threads ? 1 : 0);
            askers.emplace_back(askDistance, socket_path, mine, std::cref(stop),
                                std::ref(results[static_cast<std::size_t>(t)]));
        }
        std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
        stop.store(true);
        for (std::thread& thread : askers)
            thread.join();
        const double elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
        const uint64_t frames_after = processedFrames(socket_path);
        for (std::thread& thread : readers)
            thread.join();

        std::vector<double> latencies;
        uint64_t errors = 0;
        std::string first_error;
        for (const ThreadResult& result : results) {
            latencies.insert(latencies.end(), result.latencies_ms.begin(),
                             result.latencies_ms.end());
            if (result.errors > 0 && first_error.empty())
                first_error = result.first_error;
            errors += result.errors;
        }
        const std::size_t answered = latencies.size();
        Json out = Json::object();
        out["clients"] = clients;
        out["seconds"] = elapsed_s;
        out["requests"] = answered;
        out["rps"] = static_cast<double>(answered) / elapsed_s;
        out["p50_ms"] = percentile(latencies, 50.0);
        out["p99_ms"] = percentile(latencies, 99.0);
        out["max_ms"] =
            latencies.empty() ? 0.0 : *std::max_element(latencies.begin(), latencies.end());
        out["errors"] = errors;
        if (!first_error.empty())
            out["first_error"] = first_error;
        out["depth_events_read"] = depth_events.load();
        out["frames"] = frames_after - frames_before;
        out["fps"] = static_cast<double>(frames_after - frames_before) / elapsed_s;
        std::cout << out.dump(2) << "\n";
        return errors == 0 ? 0 : 1;
    } catch (const std::exception& e) {
        std::cerr << "socket_load: " << e.what() << "\n";
        return 1;
    }
}
