// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The handheld profile: a person moves the target through the depth range in
// front of the camera; every frame adds the ROI's features to their depth
// bins and the growing partial query is matched (Eq. (12)), as the paper's
// real-time demo does.
#include <cmath>

#include "tofmat/daemon/log.hpp"
#include "tofmat/daemon/region_matcher.hpp"

namespace tofmat::daemon {
namespace {

class HandheldProfile : public Profile {
 public:
  HandheldProfile(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table)
      : config_(c),
        table_(std::move(table)),
        matcher_(table_, candidate_indices(*table_, c.candidates), c.backend, c.method, c.open_set, c.model,
                 c.learner) {}

  std::optional<PixelRegion> input_region() const override { return config_.roi; }

  void process(const RawFrame& frame, const Emitter& emit) override {
    matcher_.decode(frame, config_.roi, decoded_);
    const RegionMatcher::Decoded& d = decoded_;
    RegionMatcher::emit_depths(d, frame, emit);
    // The corrected depth is corrected for this frame's label (none: no target, or unknown).
    const std::int64_t material = label(d, frame, emit);
    RegionMatcher::emit_corrected(d, frame, emit, *table_, [material](std::size_t) { return material; });
  }

  void reset() override {
    matcher_.reset();
    tracking_ = false;
  }

  std::optional<TargetView> target() const override { return view_; }

 private:
  // Tracks the target and emits this frame's label; returns its material's
  // table index, or -1 when there is none.
  std::int64_t label(const RegionMatcher::Decoded& d, const RawFrame& frame, const Emitter& emit) {
    const BinSpec& bins = table_->bins();
    // A target is there when most of the ROI decodes and its depth is in (or
    // near) the table's range; a jump in depth means another target. One that
    // fills the ROI outside the range cannot be labelled: that is said (status's
    // target at once; a label event out_of_range and the log when it stays),
    // never left silent.
    view_ = view_target(d.valid, d.pixels, d.median_mm, config_.min_valid_fraction, bins);
    const bool present = view_.state == "in_range";
    const bool out_of_range = view_.state == "out_of_range";
    if (!present) {
      if (tracking_) {
        matcher_.learn_sweep();  // the target left: its sweep is finished
        matcher_.reset();
        tracking_ = false;
        protocol::LabelEvent e;
        e.state = "no_target";
        emit.label(stamp(e, frame));
      }
      // A sweep passes beyond the bins at its ends as a matter of course; a target that stays
      // there for kOutOfRangeNs (a still one, or a table whose bins miss the scene) is reported,
      // once per stay: a label event, and the log (warn the first time for this table).
      if (!out_of_range) {
        reported_out_of_range_ = false;
      } else {
        if (!was_out_of_range_) out_of_range_since_ns_ = frame.arrival_ns;
        if (!reported_out_of_range_ && frame.arrival_ns >= out_of_range_since_ns_ + kOutOfRangeNs) {
          reported_out_of_range_ = true;
          if (warned_out_of_range_) {
            logger(LogCategory::kProfile).info("handheld: {}", view_.reason);
          } else {
            logger(LogCategory::kProfile).warn("handheld: {}", view_.reason);
            warned_out_of_range_ = true;
          }
          protocol::LabelEvent e;
          e.state = "out_of_range";
          emit.label(stamp(e, frame));
        }
      }
      was_out_of_range_ = out_of_range;
      return -1;
    }
    was_out_of_range_ = false;
    reported_out_of_range_ = false;
    if (tracking_ && std::abs(d.median_mm - last_mm_) > config_.jump_mm) {
      matcher_.learn_sweep();  // another target: the last one's sweep is finished
      matcher_.reset();
    }
    tracking_ = true;
    last_mm_ = d.median_mm;
    matcher_.accumulate(d);
    if (const auto c = matcher_.classify()) {
      auto e = matcher_.label_event(*c, config_.top_k);
      e.state = matcher_.unknown(*c) ? "unknown" : "tracking";
      emit.label(stamp(e, frame));
      return e.index;  // (-1 when unknown)
    }
    return -1;
  }
  protocol::LabelEvent& stamp(protocol::LabelEvent& e, const RawFrame& frame) const {
    e.frame = frame.sequence;
    e.timestamp_ns = frame.arrival_ns;
    e.profile = "handheld";
    e.truth = region_truth(frame, config_.roi);
    e.simulated = frame.simulated;
    return e;
  }

  ProfileConfig config_;
  std::shared_ptr<const ExemplarTable> table_;
  RegionMatcher matcher_;
  RegionMatcher::Decoded decoded_;  // this frame's ROI (its buffers reused frame after frame)
  bool tracking_ = false;
  static constexpr std::uint64_t kOutOfRangeNs = 1'000'000'000ull;
  bool was_out_of_range_ = false;       // the last frame's target was out of the table's range
  bool reported_out_of_range_ = false;  // this stay out of range has had its label event
  bool warned_out_of_range_ = false;    // the log warned once for this table (a reload makes a new profile)
  std::uint64_t out_of_range_since_ns_ = 0;
  double last_mm_ = 0.0;
  TargetView view_;
};

}  // namespace

std::unique_ptr<Profile> make_handheld(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table) {
  return std::make_unique<HandheldProfile>(c, std::move(table));
}

}  // namespace tofmat::daemon
