// The processing stage: frames from the source's bounded queue (the oldest is
// dropped when processing falls behind, so the camera is never blocked) go
// through the active profile; commands from clients change the profile, ROI,
// candidates or table between frames. A command that would break the
// pipeline (unknown profile, bad ROI, a table that does not load or fit) is
// refused with a reason and nothing changes.
#pragma once
#include <atomic>
#include <deque>
#include <memory>
#include <mutex>

#include <nlohmann/json.hpp>

#include "tofmat/daemon/bounded_queue.hpp"
#include "tofmat/daemon/profile.hpp"

namespace tofmat::daemon {

class Pipeline {
 public:
  Pipeline(std::shared_ptr<const ExemplarTable> table, std::string table_path, ProfileConfig config,
           std::size_t queue_frames = 2);

  void set_emitter(Emitter emit) { emit_ = std::move(emit); }  // before run()
  void push(RawFrame&& frame) { queue_.push(std::move(frame)); }
  // The processing thread's loop, until stop is set.
  void run(const std::atomic<bool>& stop);

  // Commands (any thread). Each throws std::invalid_argument (or
  // std::logic_error for a trigger outside sorting) and changes nothing then.
  void reset();
  void set_profile(const std::string& name);
  void set_roi(const PixelRegion& roi);
  void set_candidates(const std::vector<std::string>& names);
  void set_table(std::shared_ptr<const ExemplarTable> table, const std::string& path);
  std::uint64_t trigger(int burst);

  ProfileConfig config() const;
  std::string table_path() const;
  std::shared_ptr<const ExemplarTable> table() const;
  nlohmann::json status() const;

 private:
  void apply(const ProfileConfig& config, std::shared_ptr<const ExemplarTable> table, const std::string& path);

  BoundedQueue<RawFrame> queue_;
  Emitter emit_;
  mutable std::mutex mutex_;  // held while a frame is processed and while a command swaps state
  std::shared_ptr<const ExemplarTable> table_;
  std::string table_path_;
  ProfileConfig config_;
  std::unique_ptr<Profile> profile_;
  // Statistics (under mutex_).
  std::uint64_t processed_ = 0, errors_ = 0;
  std::deque<std::uint64_t> recent_ns_;  // arrival times of the last second's frames
  double process_ms_ewma_ = 0.0;
  std::string last_error_;
};

}  // namespace tofmat::daemon
