#pragma once
// Rows of an image shared out over OpenCV's thread pool (cv::parallel_for_) in stripes of
// about 16 rows, for the per-pixel passes whose rows are independent (the rectification,
// the passes after the match): the pool's threads would otherwise wait while this thread
// works. The body is a class on the caller's stack taken by reference (no std::function),
// so a call allocates nothing once the pool has started.
//
// OpenCV's pool (TBB here) is not built with ThreadSanitizer, which therefore cannot see
// that the stripes finish before the call returns: under TSan the body tells it, so that
// the caller's later use of what the stripes wrote is not reported as a race.
//
// Reentrant; `f(first, end)` runs on several threads at once, each with its own rows, and
// must write nothing another stripe reads.

#include <opencv2/core/utility.hpp>

#if defined(__SANITIZE_THREAD__)
#define STEREOD_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define STEREOD_TSAN 1
#endif
#endif

#if defined(STEREOD_TSAN)
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
#endif

namespace stereod {

template <class F> void forRowStripes(int begin, int end, const F& f)
{
    if (end <= begin)
        return;
    class Body final : public cv::ParallelLoopBody {
      public:
        explicit Body(const F& f) : f_(f) {}
        void operator()(const cv::Range& rows) const override
        {
#if defined(STEREOD_TSAN)
            __tsan_acquire(const_cast<Body*>(this)); // after the caller's writes
            f_(rows.start, rows.end);
            __tsan_release(const_cast<Body*>(this)); // before the caller's return
#else
            f_(rows.start, rows.end);
#endif
        }

      private:
        const F& f_;
    };
    Body body(f);
#if defined(STEREOD_TSAN)
    __tsan_release(&body);
#endif
    cv::parallel_for_(cv::Range(begin, end), body, (end - begin) / 16.0);
#if defined(STEREOD_TSAN)
    __tsan_acquire(&body);
#endif
}

} // namespace stereod
