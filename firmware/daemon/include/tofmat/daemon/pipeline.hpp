// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
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
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>

#include "tofmat/daemon/bounded_queue.hpp"
#include "tofmat/daemon/profile.hpp"

namespace tofmat::daemon {

class Pipeline {
 public:
  Pipeline(std::shared_ptr<const ExemplarTable> table, const std::string& table_path, const ProfileConfig& config,
           std::size_t queue_frames = 2);

  void set_emitter(Emitter emit) { emit_ = std::move(emit); }  // before run()
  // Queues a frame, dropping the oldest waiting one if the queue is full
  // (said at debug level: a dropped frame is processing behind the camera).
  void push(RawFrame&& frame);
  // What a camera source should unpack from its next packet: the active
  // profile's input region, nothing between sorting bursts (any thread).
  std::optional<PixelRegion> wanted_region() const;
  // A buffer for a frame's raw samples, recycled from processed frames so a
  // frame costs no 3.9 MB allocation and zero-fill (any thread).
  std::vector<std::int16_t> raw_buffer();
  // For a source that must lose no frame (Source::lossless): waits for room;
  // false once stop is set.
  bool push_wait(RawFrame&& frame, const std::atomic<bool>& stop) { return queue_.push_wait(std::move(frame), stop); }
  // The processing thread's loop, until stop is set.
  void run(const std::atomic<bool>& stop);

  // Commands (any thread). Each throws std::invalid_argument (or
  // std::logic_error for a trigger outside sorting) and changes nothing then.
  void reset();
  // A new session: the session matcher's learned weights start again
  // (also on a new table, candidate list or backend).
  void reset_session();
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
  // Serialises the commands that change the configuration: each reads it,
  // changes one thing and applies the whole (two clients' commands at once
  // must not undo each other). Held while a new profile is built, outside
  // mutex_, so frames keep flowing meanwhile.
  std::mutex commands_mutex_;
  std::shared_ptr<const ExemplarTable> table_;
  std::string table_path_;
  ProfileConfig config_;
  std::unique_ptr<Profile> profile_;
  // The session's learner (session_learner.hpp), kept while the table,
  // candidates and backend stay (a profile or ROI change is the same session).
  std::shared_ptr<SessionLearner> learner_;
  // Statistics (under mutex_).
  std::uint64_t processed_ = 0, errors_ = 0;
  std::deque<std::uint64_t> recent_ns_;  // arrival times of the last second's frames
  std::uint64_t skipped_ = 0;            // unpacked for another profile's region (a switch in flight)
  // What the source should unpack, and spare sample buffers (under source_mutex_).
  void publish_wanted_region();  // with mutex_ held
  mutable std::mutex source_mutex_;
  std::optional<PixelRegion> wanted_;
  std::vector<std::vector<std::int16_t>> spare_raw_;
  double process_ms_ewma_ = 0.0;
  std::string last_error_;
};

}  // namespace tofmat::daemon
