#include "pipeline/sgm/band_pool.hpp"

namespace stereod::sgm {

BandPool::BandPool(int threads)
{
    for (int band = 1; band < threads; ++band)
        threads_.emplace_back([this, band] { workerLoop(band); });
}

BandPool::~BandPool()
{
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_.notify_all();
    for (std::thread& t : threads_)
        t.join();
}

void BandPool::runErased(int bands, void* context, Trampoline call)
{
    {
        std::lock_guard lock(mutex_);
        context_ = context;
        call_ = call;
        bands_ = bands;
        pending_ = bands - 1;
        ++generation_;
    }
    if (bands > 1)
        wake_.notify_all();
    call(context, 0);
    std::unique_lock lock(mutex_);
    done_.wait(lock, [this] { return pending_ == 0; });
}

void BandPool::workerLoop(int band)
{
    uint64_t seen = 0;
    std::unique_lock lock(mutex_);
    for (;;) {
        wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
        if (stop_)
            return;
        seen = generation_;
        if (band >= bands_)
            continue;
        void* context = context_;
        const Trampoline call = call_;
        lock.unlock();
        call(context, band);
        lock.lock();
        if (--pending_ == 0)
            done_.notify_one();
    }
}

} // namespace stereod::sgm
