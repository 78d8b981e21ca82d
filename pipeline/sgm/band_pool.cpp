#include "pipeline/sgm/band_pool.hpp"

#include <stdexcept>
#include <string>

namespace stereod::sgm {
namespace {

constexpr uint32_t kBandBits = 8;
constexpr uint32_t kBandMask = (1u << kBandBits) - 1;

void relax()
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__) || defined(__arm__)
    asm volatile("yield");
#endif
}

// Returns the value of `word` once it differs from `old`: spins for BandPool::kSpin, or
// until `resting` is set, then sleeps on it (std::atomic::wait, a futex).
uint32_t awaitChange(const std::atomic<uint32_t>& word, uint32_t old,
                     const std::atomic<bool>* resting = nullptr)
{
    using Clock = std::chrono::steady_clock;
    const Clock::time_point until = Clock::now() + BandPool::kSpin;
    for (int spins = 0;; ++spins) {
        const uint32_t now = word.load(std::memory_order_acquire);
        if (now != old)
            return now;
        if (resting != nullptr && resting->load(std::memory_order_relaxed))
            break;
        // The clock is read every 64 spins: a few microseconds apart.
        if ((spins & 63) == 63 && Clock::now() >= until)
            break;
        relax();
    }
    for (;;) {
        word.wait(old, std::memory_order_acquire);
        const uint32_t now = word.load(std::memory_order_acquire);
        if (now != old)
            return now;
    }
}

} // namespace

BandPool::BandPool(int threads)
{
    if (threads < 1 || threads > 64)
        throw std::invalid_argument("BandPool: threads must be 1 to 64, not " +
                                    std::to_string(threads));
    for (int band = 1; band < threads; ++band)
        threads_.emplace_back([this, band] { workerLoop(band); });
}

BandPool::~BandPool()
{
    stop_.store(true, std::memory_order_release);
    work_.fetch_add(1u << kBandBits, std::memory_order_seq_cst);
    work_.notify_all();
    for (std::thread& t : threads_)
        t.join();
}

void BandPool::rest()
{
    resting_.store(true, std::memory_order_relaxed);
}

int BandPool::threads() const
{
    return static_cast<int>(threads_.size()) + 1;
}

void BandPool::runErased(int bands, void* context, Trampoline call)
{
    resting_.store(false, std::memory_order_relaxed);
    if (bands > 1) {
        context_ = context;
        call_ = call;
        pending_.store(static_cast<uint32_t>(bands - 1), std::memory_order_relaxed);
        const uint32_t next = ((work_.load(std::memory_order_relaxed) >> kBandBits) + 1)
                              << kBandBits;
        // Sequentially consistent, not release: notify_all() skips the wake when it reads
        // no sleeper, and a thread falls asleep by announcing itself, then reading work_.
        // A release store may become visible after the read of the sleepers that follows
        // it (x86 reorders a store with a later load), and both sides would miss each
        // other: the thread asleep on a run it never sees, the caller waiting on its band.
        work_.store(next | static_cast<uint32_t>(bands), std::memory_order_seq_cst);
        work_.notify_all();
    }
    call(context, 0);
    for (uint32_t left = pending_.load(std::memory_order_acquire); bands > 1 && left != 0;)
        left = awaitChange(pending_, left);
}

void BandPool::workerLoop(int band)
{
    uint32_t seen = 0;
    for (;;) {
        seen = awaitChange(work_, seen, &resting_);
        if (stop_.load(std::memory_order_acquire))
            return;
        if (static_cast<uint32_t>(band) >= (seen & kBandMask))
            continue;
        call_(context_, band);
        if (pending_.fetch_sub(1, std::memory_order_seq_cst) == 1) // as work_ in runErased()
            pending_.notify_one();
    }
}

} // namespace stereod::sgm
