#pragma once
// A fixed set of threads that run one function over the bands of an image and wait for
// all of them: the caller's thread takes band 0, the pool's threads the others. Threads
// start in the constructor and stop in the destructor; run() allocates nothing.
//
// Thread-bound: run() is called from one thread at a time.

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

namespace stereod::sgm {

class BandPool {
  public:
    // threads: how many bands run at once, the caller's thread included (>= 1).
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

  private:
    using Trampoline = void (*)(void*, int);
    void runErased(int bands, void* context, Trampoline call);
    void workerLoop(int band);

    std::mutex mutex_;
    std::condition_variable wake_; // a new generation of work, or stop
    std::condition_variable done_; // the last band of a generation finished
    uint64_t generation_ = 0;      // guarded by mutex_
    int bands_ = 0;                // guarded by mutex_
    int pending_ = 0;              // guarded by mutex_
    bool stop_ = false;            // guarded by mutex_
    void* context_ = nullptr;      // guarded by mutex_
    Trampoline call_ = nullptr;    // guarded by mutex_
    std::vector<std::thread> threads_;
};

} // namespace stereod::sgm
