// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The handheld profile: a person moves the target through the depth range in
// front of the camera; every frame adds the ROI's features to their depth
// bins and the growing partial query is matched (Eq. (12)), as the paper's
// real-time demo does.
#include <cmath>

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
    const auto d = matcher_.decode(frame, config_.roi);
    RegionMatcher::emit_depths(d, frame, emit);
    // The corrected depth is corrected for this frame's label (none: no target, or unknown).
    const std::int64_t material = label(d, frame, emit);
    RegionMatcher::emit_corrected(d, frame, emit, *table_, [material](std::size_t) { return material; });
  }

  void reset() override {
    matcher_.reset();
    tracking_ = false;
  }

 private:
  // Tracks the target and emits this frame's label; returns its material's
  // table index, or -1 when there is none.
  std::int64_t label(const RegionMatcher::Decoded& d, const RawFrame& frame, const Emitter& emit) {
    const BinSpec& bins = table_->bins();
    // A target is there when most of the ROI decodes and its depth is in (or
    // near) the table's range; a jump in depth means another target.
    const bool present = static_cast<double>(d.valid) >= config_.min_valid_fraction * static_cast<double>(d.pixels) &&
                         d.median_mm >= bins.start_mm - 50.0 && d.median_mm <= bins.end_mm() + 50.0;
    if (!present) {
      if (tracking_) {
        matcher_.learn_sweep();  // the target left: its sweep is finished
        matcher_.reset();
        tracking_ = false;
        protocol::LabelEvent e;
        e.state = "no_target";
        emit.label(stamp(e, frame));
      }
      return -1;
    }
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
  bool tracking_ = false;
  double last_mm_ = 0.0;
};

}  // namespace

std::unique_ptr<Profile> make_handheld(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table) {
  return std::make_unique<HandheldProfile>(c, std::move(table));
}

}  // namespace tofmat::daemon
