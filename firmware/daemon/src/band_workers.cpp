// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// BandWorkers: the worker threads, one per extra band, and the hand-over of a frame's work to them.
#include "tofmat/daemon/band_workers.hpp"

#include <stdexcept>
#include <string>

namespace tofmat::daemon {

BandWorkers::BandWorkers(int bands) {
  if (bands < 1) throw std::invalid_argument("bands must be at least 1, got " + std::to_string(bands));
  workers_.reserve(static_cast<std::size_t>(bands - 1));
  for (int b = 1; b < bands; ++b) workers_.emplace_back([this, b] { work(b); });
}

BandWorkers::~BandWorkers() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  start_.notify_all();
  for (auto& t : workers_) t.join();
}

int BandWorkers::bands_for(int threads) {
  if (threads > 0) return threads;
  const unsigned cores = std::thread::hardware_concurrency();  // 0 when unknown
  return cores > 0 ? static_cast<int>(cores) : 1;
}

void BandWorkers::run(const std::function<void(int)>& fn) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    job_ = &fn;
    error_ = nullptr;
    pending_ = static_cast<int>(workers_.size());
    ++generation_;
  }
  start_.notify_all();
  std::exception_ptr mine;
  try {
    fn(0);
  } catch (...) {
    mine = std::current_exception();
  }
  std::unique_lock<std::mutex> lock(mutex_);
  done_.wait(lock, [this] { return pending_ == 0; });
  job_ = nullptr;
  if (mine) std::rethrow_exception(mine);
  if (error_) std::rethrow_exception(error_);
}

void BandWorkers::work(int band) {
  std::uint64_t seen = 0;
  for (;;) {
    const std::function<void(int)>* job = nullptr;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      start_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
      job = job_;
    }
    // Every exception is caught here and handed to run()'s caller: a worker
    // never dies with the frame's error, and the next frame finds it waiting.
    std::exception_ptr error;
    try {
      (*job)(band);
    } catch (...) {
      error = std::current_exception();
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (error && !error_) error_ = error;
      --pending_;
    }
    done_.notify_one();
  }
}

}  // namespace tofmat::daemon
