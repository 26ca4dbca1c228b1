// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Threads that share one frame's work: run(fn) calls fn(band) for every band
// in [0, bands()) at once, band 0 on the calling thread and each other band on
// a worker of its own, and returns when all have finished. The segmentation
// profile splits its full frames into bands of rows this way, so the board's
// cores share a frame (a frame's steps depend on each other; frames do not
// overlap, so labels stay in order and latency falls with the cores).
#pragma once
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace tofmat::daemon {

class BandWorkers {
 public:
  // bands >= 1 (throws std::invalid_argument otherwise); 1 starts no thread.
  explicit BandWorkers(int bands);
  // Stops and joins the workers (waking any that wait).
  ~BandWorkers();
  BandWorkers(const BandWorkers&) = delete;
  BandWorkers& operator=(const BandWorkers&) = delete;

  int bands() const { return static_cast<int>(workers_.size()) + 1; }
  // Calls fn(band) for every band; rethrows the first exception any band
  // threw, after every band has returned. Not reentrant: one caller at a time.
  void run(const std::function<void(int band)>& fn);

  // The bands for `threads` (0: every core the system reports, at least 1).
  static int bands_for(int threads);

 private:
  void work(int band);

  std::mutex mutex_;
  std::condition_variable start_, done_;
  const std::function<void(int)>* job_ = nullptr;
  std::uint64_t generation_ = 0;  // one per run()
  int pending_ = 0;               // workers still on this generation's job
  bool stop_ = false;
  std::exception_ptr error_;
  std::vector<std::thread> workers_;
};

}  // namespace tofmat::daemon
