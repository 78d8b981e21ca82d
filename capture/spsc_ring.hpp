#pragma once
// Bounded lock-free ring between one producer (a frame source) and one consumer (the
// worker). When the ring is full, push() drops the oldest item, counts the drop, and
// destroys it on the producer's thread (for frame pairs that gives the buffers back). A
// consumer that wants the freshest item rather than every item takes it with
// popNewest(), which drops and counts the older ones on the consumer's thread.
//
// Contract:
//  - exactly one producer thread calls push()/pushWait(); exactly one consumer thread
//    calls pop()/popNewest()/tryPop(); stop(), counters and size() may be called from any
//    thread;
//  - no call takes a lock; pop() and pushWait() block on atomic wait/notify (futex);
//  - stop() wakes a blocked pop() (which then returns what is still queued, then
//    nothing) and a blocked pushWait() (which then gives up and drops its item);
//  - capacity is rounded up to a power of two, at least 2.
//
// Drop-oldest needs the producer to take items from the consumer's end, so the slots
// follow Vyukov's bounded queue (a sequence number per slot): both ends claim a slot by
// CAS on its index, and a slot is reused only after its sequence says it was emptied.

#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <thread>
#include <utility>

namespace stereod {

// Keeps the two ends' indices on separate cache lines (64 bytes on the x86-64 and ARM
// cores robots use; std::hardware_destructive_interference_size is not ABI-stable).
inline constexpr std::size_t kCacheLine = 64;

template <typename T> class SpscRing {
  public:
    explicit SpscRing(std::size_t capacity)
        : capacity_(std::bit_ceil(capacity < 2 ? std::size_t{2} : capacity)), mask_(capacity_ - 1),
          slots_(std::make_unique<Slot[]>(capacity_))
    {
        for (std::size_t i = 0; i < capacity_; ++i)
            slots_[i].sequence.store(i, std::memory_order_relaxed);
    }

    SpscRing(const SpscRing&) = delete;
    SpscRing& operator=(const SpscRing&) = delete;

    // Producer. Never blocks (beyond the few instructions the consumer needs to finish
    // moving an item out). Returns false when an older item was dropped to make room.
    bool push(T&& item)
    {
        bool dropped_one = false;
        while (!tryEnqueue(item)) {
            // Drop only when the ring really holds `capacity` items. Otherwise the
            // consumer has claimed the oldest item and is still moving it out of the very
            // slot this push needs: dropping would not free that slot, it would throw away
            // newer items (all of them, were the consumer preempted mid-move).
            const std::size_t head = head_.load(std::memory_order_relaxed);
            if (head - tail_.load(std::memory_order_acquire) < capacity_) {
                std::this_thread::yield();
                continue;
            }
            if (std::optional<T> oldest = tryDequeue()) {
                dropped_.fetch_add(1, std::memory_order_relaxed);
                dropped_one = true;
            }
        }
        pushed_.fetch_add(1, std::memory_order_relaxed);
        notifyConsumer();
        return !dropped_one;
    }

    // Producer, lockstep mode: waits for room instead of dropping. Returns false (and
    // drops the item) only when the ring is stopped.
    bool pushWait(T&& item)
    {
        while (!tryEnqueue(item)) {
            const uint32_t seen = popped_epoch_.load(std::memory_order_acquire);
            if (stopped())
                return false;
            if (tryEnqueue(item))
                break;
            popped_epoch_.wait(seen, std::memory_order_acquire);
        }
        pushed_.fetch_add(1, std::memory_order_relaxed);
        notifyConsumer();
        return true;
    }

    // Consumer: the oldest item, or nothing when the ring is empty.
    std::optional<T> tryPop()
    {
        std::optional<T> item = tryDequeue();
        if (item) {
            popped_epoch_.fetch_add(1, std::memory_order_release);
            popped_epoch_.notify_one();
        }
        return item;
    }

    // Consumer: waits for an item. Returns nothing only once stopped and drained.
    std::optional<T> pop()
    {
        for (;;) {
            const uint32_t seen = pushed_epoch_.load(std::memory_order_acquire);
            if (std::optional<T> item = tryPop())
                return item;
            if (stopped())
                return std::nullopt;
            pushed_epoch_.wait(seen, std::memory_order_acquire);
        }
    }

    // Consumer: waits like pop(), then takes the newest item waiting; the older ones are
    // dropped (counted in dropped()) and destroyed here. Returns nothing only once
    // stopped and drained.
    std::optional<T> popNewest()
    {
        std::optional<T> item = pop();
        if (!item)
            return item;
        while (std::optional<T> newer = tryPop()) {
            dropped_.fetch_add(1, std::memory_order_relaxed);
            item.reset(); // the older item's resources go back before the newer is held
            item.swap(newer);
        }
        return item;
    }

    // Any thread. Wakes both ends; later pushes still work but pop() no longer waits.
    void stop()
    {
        stopped_.store(true, std::memory_order_release);
        pushed_epoch_.fetch_add(1, std::memory_order_release);
        pushed_epoch_.notify_all();
        popped_epoch_.fetch_add(1, std::memory_order_release);
        popped_epoch_.notify_all();
    }

    // Any thread: re-arms a stopped ring (items still queued stay queued).
    void restart() { stopped_.store(false, std::memory_order_release); }

    bool stopped() const { return stopped_.load(std::memory_order_acquire); }
    std::size_t capacity() const { return capacity_; }
    uint64_t pushed() const { return pushed_.load(std::memory_order_relaxed); }
    // Items dropped: by push() on a full ring, and by popNewest() for a newer one.
    uint64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }

    // Any thread; exact only when neither end is moving.
    std::size_t size() const
    {
        const std::size_t head = head_.load(std::memory_order_acquire);
        const std::size_t tail = tail_.load(std::memory_order_acquire);
        return head >= tail ? head - tail : 0;
    }

  private:
    struct Slot {
        std::atomic<std::size_t> sequence{0};
        std::optional<T> value;
    };

    // Only the producer enqueues, so head_ needs no CAS.
    bool tryEnqueue(T& item)
    {
        const std::size_t pos = head_.load(std::memory_order_relaxed);
        Slot& slot = slots_[pos & mask_];
        if (slot.sequence.load(std::memory_order_acquire) != pos)
            return false; // full, or the consumer is still moving this slot's old item out
        slot.value.emplace(std::move(item));
        slot.sequence.store(pos + 1, std::memory_order_release);
        head_.store(pos + 1, std::memory_order_release);
        return true;
    }

    // Called by the consumer, and by the producer when it drops the oldest item.
    std::optional<T> tryDequeue()
    {
        std::size_t pos = tail_.load(std::memory_order_relaxed);
        for (;;) {
            Slot& slot = slots_[pos & mask_];
            const std::size_t seq = slot.sequence.load(std::memory_order_acquire);
            const auto diff =
                static_cast<std::ptrdiff_t>(seq) - static_cast<std::ptrdiff_t>(pos + 1);
            if (diff == 0) {
                if (tail_.compare_exchange_weak(pos, pos + 1, std::memory_order_acq_rel,
                                                std::memory_order_relaxed)) {
                    std::optional<T> out(std::move(slot.value));
                    slot.value.reset();
                    slot.sequence.store(pos + capacity_, std::memory_order_release);
                    return out;
                }
            } else if (diff < 0) {
                return std::nullopt; // empty
            } else {
                pos = tail_.load(std::memory_order_relaxed);
            }
        }
    }

    void notifyConsumer()
    {
        pushed_epoch_.fetch_add(1, std::memory_order_release);
        pushed_epoch_.notify_one();
    }

    const std::size_t capacity_;
    const std::size_t mask_;
    std::unique_ptr<Slot[]> slots_;

    alignas(kCacheLine) std::atomic<std::size_t> head_{0};
    alignas(kCacheLine) std::atomic<std::size_t> tail_{0};
    alignas(kCacheLine) std::atomic<uint32_t> pushed_epoch_{0};
    alignas(kCacheLine) std::atomic<uint32_t> popped_epoch_{0};
    std::atomic<uint64_t> pushed_{0};
    std::atomic<uint64_t> dropped_{0};
    std::atomic<bool> stopped_{false};
};

} // namespace stereod
