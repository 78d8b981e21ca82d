#pragma once
// A fixed set of threads that run one function over the bands of an image and wait for
// all of them: the caller's thread takes band 0, the pool's threads the others. Threads
// start in the constructor and stop in the destructor; run() allocates nothing.
//
// A matcher calls run() a dozen times per frame, a few hundred microseconds apart. A
// thread put to sleep between two of them takes tens to hundreds of microseconds to be
// scheduled again (more on a loaded or virtual machine), so the pool's threads, and the
// caller waiting for them, first spin for a short while (kSpin) before they sleep: within
// a frame they rarely sleep, between frames they do.
//
// Thread-bound: run() is called from one thread at a time.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <thread>
#include <type_traits>
#include <vector>

namespace stereod::sgm {

class BandPool {
  public:
    // How long a thread spins on its condition before it sleeps.
    static constexpr std::chrono::microseconds kSpin{100};

    // threads: how many bands run at once, the caller's thread included (1 to 64).
    explicit BandPool(int threads);
    ~BandPool();

    BandPool(const BandPool&) = delete;
    BandPool& operator=(const BandPool&) = delete;

    // Calls work(band) for band = 0 .. bands-1 (bands <= threads), one band per thread,
    // and returns when all have returned. `work` must not throw.
    template <typename Work> void run(int bands, Work&& work)
    {
        runErased(bands, &work, [](void* context, int band) {
            (*static_cast<std::remove_reference_t<Work>*>(context))(band);
        });
    }

    int threads() const;

    // Tells the pool's threads that no run follows soon (the caller's work with the pool
    // is done for this frame): they sleep at once rather than spin, leaving the cores to
    // what runs next. The next run() wakes them as usual.
    void rest();

  private:
    using Trampoline = void (*)(void*, int);
    void runErased(int bands, void* context, Trampoline call);
    void workerLoop(int band);

    // One word, so that a thread which sits a run out (its band >= the run's bands) reads
    // nothing else of it: the run's number << 8 | its bands. The number wraps; threads
    // compare it for a change only.
    std::atomic<uint32_t> work_{0};
    std::atomic<uint32_t> pending_{0}; // bands of the current run not yet returned
    std::atomic<bool> stop_{false};
    std::atomic<bool> resting_{false}; // rest() until the next run()
    // Written before work_ announces a run, read only by the bands that take part in it.
    void* context_ = nullptr;
    Trampoline call_ = nullptr;
    std::vector<std::thread> threads_;
};

} // namespace stereod::sgm
