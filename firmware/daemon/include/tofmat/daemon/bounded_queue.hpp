// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A bounded queue between two threads. push() never blocks the producer:
// when the queue is full it drops the oldest item (a camera frame that waited
// too long is worth less than the new one) and counts it. push_wait() is for
// a producer that must lose nothing (a replay as fast as it is processed): it
// waits for room, and gives up when stop is set or the queue is closed.
#pragma once
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>

namespace tofmat::daemon {

template <typename T>
class BoundedQueue {
 public:
  explicit BoundedQueue(std::size_t capacity) : capacity_(capacity < 1 ? 1 : capacity) {}

  void push(T item) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (items_.size() >= capacity_) {
        items_.pop_front();
        ++dropped_;
      }
      items_.push_back(std::move(item));
    }
    ready_.notify_one();
  }

  // Waits until there is room, then appends. Returns false (item not queued)
  // once `stop` is set or the queue is closed; `stop` is polled every 50 ms,
  // so the wait ends promptly even if nobody closes the queue.
  bool push_wait(T item, const std::atomic<bool>& stop) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      while (items_.size() >= capacity_ && !closed_) {
        if (stop.load()) return false;
        space_.wait_for(lock, std::chrono::milliseconds(50));
      }
      if (closed_ || stop.load()) return false;
      items_.push_back(std::move(item));
    }
    ready_.notify_one();
    return true;
  }

  // The oldest item, or nothing after `timeout` or once closed and empty.
  std::optional<T> pop(std::chrono::milliseconds timeout) {
    std::optional<T> item;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      ready_.wait_for(lock, timeout, [&] { return !items_.empty() || closed_; });
      if (items_.empty()) return std::nullopt;
      item = std::move(items_.front());
      items_.pop_front();
    }
    space_.notify_one();
    return item;
  }

  void close() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
    space_.notify_all();
  }

  std::uint64_t dropped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_;
  }
  std::size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return items_.size();
  }

 private:
  const std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable ready_, space_;
  std::deque<T> items_;
  std::uint64_t dropped_ = 0;
  bool closed_ = false;
};

}  // namespace tofmat::daemon
