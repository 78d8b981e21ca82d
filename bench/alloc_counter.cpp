#include "bench/alloc_counter.hpp"

#include <atomic>
#include <cstdlib>
#include <new>

#include <opencv2/core/mat.hpp>

namespace {

std::atomic<uint64_t> g_cpp_allocations{0};
std::atomic<uint64_t> g_mat_allocations{0};

void* countedAlloc(std::size_t bytes) noexcept
{
    g_cpp_allocations.fetch_add(1, std::memory_order_relaxed);
    // malloc(0) may return nullptr; operator new must return a unique pointer.
    return std::malloc(bytes == 0 ? 1 : bytes);
}

void* countedAlignedAlloc(std::size_t bytes, std::align_val_t alignment) noexcept
{
    g_cpp_allocations.fetch_add(1, std::memory_order_relaxed);
    // posix_memalign wants a power of two that is a multiple of sizeof(void*).
    std::size_t align = static_cast<std::size_t>(alignment);
    if (align < sizeof(void*)) {
        align = sizeof(void*);
    }
    void* p = nullptr;
    if (posix_memalign(&p, align, bytes == 0 ? 1 : bytes) != 0) {
        return nullptr;
    }
    return p;
}

void* orThrow(void* p)
{
    if (p == nullptr) {
        throw std::bad_alloc();
    }
    return p;
}

// Counts each cv::Mat buffer, then lets OpenCV's standard allocator do the work. The
// UMatData it returns names the standard allocator as its owner, so buffers are released
// by it directly and this wrapper never sees a deallocation of its own.
class CountingMatAllocator final : public cv::MatAllocator {
  public:
    cv::UMatData* allocate(int dims, const int* sizes, int type, void* data, size_t* step,
                           cv::AccessFlag flags, cv::UMatUsageFlags usage) const override
    {
        if (data == nullptr) {
            g_mat_allocations.fetch_add(1, std::memory_order_relaxed);
        }
        return std_->allocate(dims, sizes, type, data, step, flags, usage);
    }

    bool allocate(cv::UMatData* data, cv::AccessFlag flags, cv::UMatUsageFlags usage) const override
    {
        return std_->allocate(data, flags, usage);
    }

    void deallocate(cv::UMatData* data) const override { std_->deallocate(data); }

  private:
    cv::MatAllocator* std_ = cv::Mat::getStdAllocator();
};

} // namespace

// Replacements of every form of the global allocation functions ([new.delete]). They are
// defined once, here, for the whole benchmark binary.
void* operator new(std::size_t bytes)
{
    return orThrow(countedAlloc(bytes));
}
void* operator new[](std::size_t bytes)
{
    return orThrow(countedAlloc(bytes));
}
void* operator new(std::size_t bytes, const std::nothrow_t&) noexcept
{
    return countedAlloc(bytes);
}
void* operator new[](std::size_t bytes, const std::nothrow_t&) noexcept
{
    return countedAlloc(bytes);
}
void* operator new(std::size_t bytes, std::align_val_t alignment)
{
    return orThrow(countedAlignedAlloc(bytes, alignment));
}
void* operator new[](std::size_t bytes, std::align_val_t alignment)
{
    return orThrow(countedAlignedAlloc(bytes, alignment));
}
void* operator new(std::size_t bytes, std::align_val_t alignment, const std::nothrow_t&) noexcept
{
    return countedAlignedAlloc(bytes, alignment);
}
void* operator new[](std::size_t bytes, std::align_val_t alignment, const std::nothrow_t&) noexcept
{
    return countedAlignedAlloc(bytes, alignment);
}

void operator delete(void* p) noexcept
{
    std::free(p);
}
void operator delete[](void* p) noexcept
{
    std::free(p);
}
void operator delete(void* p, std::size_t) noexcept
{
    std::free(p);
}
void operator delete[](void* p, std::size_t) noexcept
{
    std::free(p);
}
void operator delete(void* p, const std::nothrow_t&) noexcept
{
    std::free(p);
}
void operator delete[](void* p, const std::nothrow_t&) noexcept
{
    std::free(p);
}
void operator delete(void* p, std::align_val_t) noexcept
{
    std::free(p);
}
void operator delete[](void* p, std::align_val_t) noexcept
{
    std::free(p);
}
void operator delete(void* p, std::size_t, std::align_val_t) noexcept
{
    std::free(p);
}
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept
{
    std::free(p);
}
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept
{
    std::free(p);
}
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept
{
    std::free(p);
}

namespace stereod::bench {

uint64_t cppAllocationCount() noexcept
{
    return g_cpp_allocations.load(std::memory_order_relaxed);
}

uint64_t matAllocationCount() noexcept
{
    return g_mat_allocations.load(std::memory_order_relaxed);
}

void installCountingMatAllocator()
{
    // Lives for the whole program: Mats allocated through it may outlive any scope.
    static CountingMatAllocator allocator;
    cv::Mat::setDefaultAllocator(&allocator);
}

} // namespace stereod::bench
