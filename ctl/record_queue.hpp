#pragma once
// The recorder's pair buffers and its writer thread (`stereoctl record`, ctl/record_command.cpp):
// a fixed pool of RawPairs that the socket reader fills and a writer thread writes, so
// that a disk slower than the cameras drops pairs instead of holding the socket.
//
// Thread contract: PairQueue is thread-safe (reader and writer); a RawPair belongs to
// whoever holds its index (see PairQueue::buffer()); PairWriter is made and joined by the
// reader thread. Ownership: the queue owns the buffers; the writer borrows the queue.
// Units: stamps in ns.

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "ctl/raw_pair.hpp"

namespace stereod {

// Pair buffers travelling between the socket reader and the writer thread: a fixed set,
// each either free or queued for writing.
//
// Thread-safe: every member function may be called from either thread.
class PairQueue {
  public:
    explicit PairQueue(std::size_t capacity) : buffers_(capacity)
    {
        for (std::size_t i = 0; i < capacity; ++i) {
            free_.push_back(i);
        }
    }

    // A free buffer for the reader to fill, or none when all are queued or being written.
    std::optional<std::size_t> takeFree()
    {
        std::lock_guard lock(mutex_);
        if (free_.empty()) {
            return std::nullopt;
        }
        const std::size_t index = free_.back();
        free_.pop_back();
        return index;
    }
    // The reader could not fill it after all.
    void giveBack(std::size_t index)
    {
        std::lock_guard lock(mutex_);
        free_.push_back(index);
    }
    void push(std::size_t index)
    {
        {
            std::lock_guard lock(mutex_);
            ready_.push_back(index);
        }
        changed_.notify_all();
    }
    // The next buffer to write; none once close() was called and nothing is left.
    std::optional<std::size_t> pop()
    {
        std::unique_lock lock(mutex_);
        changed_.wait(lock, [&] { return !ready_.empty() || closed_; });
        if (ready_.empty()) {
            return std::nullopt;
        }
        const std::size_t index = ready_.front();
        ready_.pop_front();
        return index;
    }
    // The writer is done with it.
    void release(std::size_t index) { giveBack(index); }
    // No more pairs will come; pop() drains what is queued, then returns none.
    void close()
    {
        {
            std::lock_guard lock(mutex_);
            closed_ = true;
        }
        changed_.notify_all();
    }
    std::size_t queued() const
    {
        std::lock_guard lock(mutex_);
        return ready_.size();
    }
    std::size_t capacity() const noexcept { return buffers_.size(); }
    // Owned by whoever took the index: the reader between takeFree() and push(), the
    // writer between pop() and release().
    RawPair& buffer(std::size_t index) { return buffers_[index]; }

  private:
    std::vector<RawPair> buffers_;
    mutable std::mutex mutex_;
    std::condition_variable changed_;
    std::vector<std::size_t> free_; // guarded by mutex_
    std::deque<std::size_t> ready_; // guarded by mutex_
    bool closed_ = false;           // guarded by mutex_
};

// The writer thread: writes queued pairs until the queue is closed and drained, or a write
// fails (then it stops and keeps the error; the reader sees failed()).
//
// Thread contract: constructed and joined by the reader thread; written() and failed()
// from any thread.
class PairWriter {
  public:
    using WriteFn = std::function<void(const RawPair&)>;

    PairWriter(WriteFn write, PairQueue& queue) : write_(std::move(write)), queue_(queue)
    {
        thread_ = std::thread([this] { run(); });
    }
    // Closes the queue (pairs queued are still written) and waits for the thread.
    ~PairWriter()
    {
        queue_.close();
        join();
    }
    PairWriter(const PairWriter&) = delete;
    PairWriter& operator=(const PairWriter&) = delete;

    void join()
    {
        if (thread_.joinable()) {
            thread_.join();
        }
    }
    uint64_t written() const noexcept { return written_.load(std::memory_order_acquire); }
    bool failed() const noexcept { return failed_.load(std::memory_order_acquire); }
    // The failure, once failed() is true.
    std::string error() const
    {
        std::lock_guard lock(error_mutex_);
        return error_;
    }

  private:
    void run()
    {
        while (const std::optional<std::size_t> index = queue_.pop()) {
            if (!failed()) {
                const RawPair& pair = queue_.buffer(*index);
                try {
                    write_(pair);
                    written_.fetch_add(1, std::memory_order_acq_rel);
                } catch (const std::exception& e) {
                    {
                        std::lock_guard lock(error_mutex_);
                        error_ = e.what();
                    }
                    failed_.store(true, std::memory_order_release);
                }
            }
            queue_.release(*index);
        }
    }

    WriteFn write_;
    PairQueue& queue_;
    std::thread thread_;
    std::atomic<uint64_t> written_{0};
    std::atomic<bool> failed_{false};
    mutable std::mutex error_mutex_;
    std::string error_; // guarded by error_mutex_
};

} // namespace stereod
