// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Pipeline: the processing thread's frame loop, and the commands that change its profile, ROI, candidates or table.
#include "tofmat/daemon/pipeline.hpp"

#include <spdlog/fmt/ranges.h>

#include <chrono>

#include "tofmat/daemon/log.hpp"
#include "tofmat/protocol/socket.hpp"

namespace tofmat::daemon {

Pipeline::Pipeline(std::shared_ptr<const ExemplarTable> table, const std::string& table_path,
                   const ProfileConfig& config, std::size_t queue_frames)
    : queue_(queue_frames) {
  apply(config, std::move(table), table_path);
}

void Pipeline::apply(const ProfileConfig& requested, std::shared_ptr<const ExemplarTable> table,
                     const std::string& path) {
  ProfileConfig config = requested;
  config.learner = nullptr;
  if (config.method == Method::kSession && config.session_learning) {
    validate(config, *table);  // (before the learner: its candidates must exist)
    const bool same =
        learner_ && table == table_ && config.candidates == config_.candidates && config.backend == config_.backend;
    config.learner = same ? learner_
                          : SessionLearner::make(table, SessionPrior::tuned(*table), config.backend == Backend::kFixed,
                                                 {}, candidate_indices(*table, config.candidates));
  }
  auto profile = make_profile(config, table);  // validates; throws before anything changes
  std::lock_guard<std::mutex> lock(mutex_);
  profile_ = std::move(profile);
  learner_ = config.learner;
  config_ = config;
  table_ = std::move(table);
  table_path_ = path;
  publish_wanted_region();
}

void Pipeline::publish_wanted_region() {
  const auto wanted = profile_->input_region();
  std::lock_guard<std::mutex> lock(source_mutex_);
  wanted_ = wanted;
}

std::optional<PixelRegion> Pipeline::wanted_region() const {
  std::lock_guard<std::mutex> lock(source_mutex_);
  return wanted_;
}

std::vector<std::int16_t> Pipeline::raw_buffer() {
  {
    std::lock_guard<std::mutex> lock(source_mutex_);
    if (!spare_raw_.empty()) {
      auto buffer = std::move(spare_raw_.back());
      spare_raw_.pop_back();
      return buffer;
    }
  }
  return std::vector<std::int16_t>(9 * kPixels);
}

void Pipeline::push(RawFrame&& frame) {
  const std::uint64_t sequence = frame.sequence, before = queue_.dropped();
  queue_.push(std::move(frame));
  if (queue_.dropped() != before)
    logger(LogCategory::kPipeline)
        .debug("frame {} queued, an older one dropped: processing is behind the camera ({} dropped so far)", sequence,
               queue_.dropped());
}

void Pipeline::run(const std::atomic<bool>& stop) {
  while (!stop.load()) {
    auto frame = queue_.pop(std::chrono::milliseconds(100));
    if (!frame) continue;
    if (!frame->calibration) continue;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto needed = profile_->input_region();
      const bool has_samples = frame->raw.size() == 9 * kPixels;
      if (needed && !region_empty(*needed) && !(has_samples && region_covers(frame->region, *needed))) {
        // Unpacked for the profile before a switch (or a trigger) took effect:
        // its pixels are not the ones needed now.
        ++skipped_;
      } else {
        const auto t0 = std::chrono::steady_clock::now();
        try {
          profile_->process(*frame, emit_);
          ++processed_;
        } catch (const std::exception& e) {
          // One bad frame costs itself only; say it once per distinct reason.
          ++errors_;
          if (last_error_ != e.what())
            logger(LogCategory::kPipeline).error("processing frame {}: {}", frame->sequence, e.what());
          last_error_ = e.what();
        }
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        process_ms_ewma_ = processed_ + errors_ <= 1 ? ms : 0.9 * process_ms_ewma_ + 0.1 * ms;
        recent_ns_.push_back(frame->arrival_ns);
        while (!recent_ns_.empty() && recent_ns_.front() + 1'000'000'000ull < frame->arrival_ns) recent_ns_.pop_front();
      }
      publish_wanted_region();  // a burst may have ended
    }
    if (frame->raw.size() == 9 * kPixels) {
      std::lock_guard<std::mutex> lock(source_mutex_);
      if (spare_raw_.size() < 4) spare_raw_.push_back(std::move(frame->raw));
    }
  }
}

void Pipeline::reset() {
  std::lock_guard<std::mutex> lock(mutex_);
  profile_->reset();
  publish_wanted_region();
}

void Pipeline::reset_session() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (learner_) learner_->reset();
}

void Pipeline::set_profile(const std::string& name) {
  std::lock_guard<std::mutex> command(commands_mutex_);  // read, change, apply: one command at a time
  auto c = config();
  c.name = name;
  apply(c, table(), table_path());
  logger(LogCategory::kProfile).info("profile {}", name);
}

void Pipeline::set_roi(const PixelRegion& roi) {
  std::lock_guard<std::mutex> command(commands_mutex_);  // read, change, apply: one command at a time
  auto c = config();
  c.roi = roi;
  apply(c, table(), table_path());
  logger(LogCategory::kProfile).info("region of interest {},{},{},{}", roi.x0, roi.y0, roi.x1, roi.y1);
}

void Pipeline::set_candidates(const std::vector<std::string>& names) {
  std::lock_guard<std::mutex> command(commands_mutex_);  // read, change, apply: one command at a time
  auto c = config();
  c.candidates = names;
  apply(c, table(), table_path());
  if (names.empty())
    logger(LogCategory::kProfile).info("candidates: all of the table's");
  else
    logger(LogCategory::kProfile).info("candidates: {}", fmt::join(names, ","));
}

void Pipeline::set_table(std::shared_ptr<const ExemplarTable> table, const std::string& path) {
  std::lock_guard<std::mutex> command(commands_mutex_);  // read, change, apply: one command at a time
  auto c = config();
  // Candidates the new table lacks would make it unusable: refuse, keep the old.
  apply(c, std::move(table), path);
}

std::uint64_t Pipeline::trigger(int burst) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto n = profile_->trigger(burst);
  publish_wanted_region();  // the burst's frames need the belt's ROI
  return n;
}

ProfileConfig Pipeline::config() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return config_;
}
std::string Pipeline::table_path() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return table_path_;
}
std::shared_ptr<const ExemplarTable> Pipeline::table() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return table_;
}

nlohmann::json Pipeline::status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto& r = config_.roi;
  nlohmann::json s = {{"profile", config_.name},
                      {"backend", config_.backend == Backend::kFixed ? "fixed" : "float"},
                      {"classifier", method_name(config_.method)},
                      {"open_set", config_.open_set},
                      {"roi", {r.x0, r.y0, r.x1, r.y1}},
                      {"candidates", config_.candidates},
                      {"table",
                       {{"path", table_path_},
                        {"materials", table_->materials()},
                        {"bins", table_->n_bins()},
                        {"bin_start_mm", table_->bins().start_mm},
                        {"bin_width_mm", table_->bins().width_mm}}},
                      {"frames_processed", processed_},
                      {"frames_dropped", queue_.dropped()},
                      {"frames_skipped", skipped_},
                      {"processing_errors", errors_},
                      {"last_error", last_error_},
                      {"fps", static_cast<double>(recent_ns_.size())},
                      {"process_ms", process_ms_ewma_}};
  if (const auto t = profile_->target()) {  // (minor 11)
    s["target"] = {{"state", t->state}, {"depth_mm", t->depth_mm}};
    if (!t->reason.empty()) s["target"]["reason"] = t->reason;
  }
  if (config_.method == Method::kOnnx) s["model"] = config_.model.path;  // (minor 8)
  if (learner_) {                                                        // (minor 10)
    const auto l = learner_->state();
    s["session"] = {{"sweeps", l.sweeps}, {"scale", l.scale}, {"scales", l.scales}, {"weights", l.weights}};
    if (!l.offsets_mm.empty()) {  // (minor 12) where the session moved
      s["session"]["offsets_mm"] = l.offsets_mm;
      s["session"]["drift_mm"] = l.drift_mm;
    }
  }
  return s;
}

}  // namespace tofmat::daemon
