#pragma once
// Allocation counting for the benchmarks: the check that process() allocates nothing in
// steady state.
//
// Two counters, because OpenCV allocates in two ways:
//  - C++ allocations: every form of the global operator new is replaced in the benchmark
//    binary (alloc_counter.cpp) by a counting one. Shared libraries resolve operator new
//    to the executable's definition, so std::vector growth and cv::AutoBuffer inside
//    OpenCV are counted too, on every thread.
//  - cv::Mat buffers: cv::Mat::create() takes memory from cv::fastMalloc, which does not
//    go through operator new. installCountingMatAllocator() puts a counting wrapper
//    around OpenCV's standard allocator so each new Mat buffer is counted as well. (A new
//    Mat buffer also costs one operator new, for its UMatData header.)
// Neither sees malloc() or cv::fastMalloc() called directly inside a library.
//
// Thread-safe: the counters are relaxed atomics; reading them is safe from any thread.

#include <cstdint>

namespace stereod::bench {

// Number of global operator new calls (all forms) since the program started.
uint64_t cppAllocationCount() noexcept;

// Number of cv::Mat buffers allocated through OpenCV's default allocator since
// installCountingMatAllocator() was called.
uint64_t matAllocationCount() noexcept;

// Makes a counting wrapper around cv::Mat's standard allocator the default allocator.
// Call once, before any benchmark runs; idempotent.
void installCountingMatAllocator();

// Counts the allocations of both kinds made between construction and the reads.
// Thread-bound (the snapshot is plain data), but the allocations it counts may come from
// any thread, e.g. OpenCV's parallel_for workers.
class AllocationWindow {
  public:
    AllocationWindow() noexcept : cpp_start_(cppAllocationCount()), mat_start_(matAllocationCount())
    {
    }
    uint64_t cppAllocations() const noexcept { return cppAllocationCount() - cpp_start_; }
    uint64_t matAllocations() const noexcept { return matAllocationCount() - mat_start_; }

  private:
    uint64_t cpp_start_;
    uint64_t mat_start_;
};

} // namespace stereod::bench
