// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The sorting profile: an item on the belt passes the ROI; a trigger (the
// light barrier's GPIO line, or a socket command) starts a burst of frames
// that are classified once. Between bursts the frames are left alone:
// nothing is decoded.
//
// A burst's frames must all show one item. On a belt packed tight, the
// burst's first and last frames can catch the item before and the one after
// in the ROI, and their mixed features average into a label that is neither
// (issue 17: at 1 m/s a packed belt sent a fifth of its items to a wrong
// outlet). So each frame is classified on its own too (Eq. (12) on that
// frame alone), and the burst keeps only the frames whose label is the
// burst's majority; the item's label is Eq. (12) on those frames together.
// With no strict majority, or when the kept frames together say another
// material, the burst's state is "mixed": the line rejects it.
#include "tofmat/daemon/log.hpp"
#include "tofmat/daemon/region_matcher.hpp"

#include <map>

namespace tofmat::daemon {
namespace {

class SortingProfile : public Profile {
 public:
  SortingProfile(const ProfileConfig& c, const std::shared_ptr<const ExemplarTable>& table)
      : config_(c),
        table_(table),
        matcher_(table, candidate_indices(*table, c.candidates), c.backend, c.method, c.open_set, c.model, c.learner),
        frame_matcher_(matcher_.twin()) {}  // (one classifier for both: a learned model is loaded once)

  std::uint64_t trigger(int burst) override {
    matcher_.reset();
    frames_.clear();
    remaining_ = burst > 0 ? burst : config_.burst;
    return ++trigger_;
  }

  std::optional<PixelRegion> input_region() const override {
    if (remaining_ == 0) return std::nullopt;  // between bursts: no pixel at all
    return config_.roi;
  }

  void process(const RawFrame& frame, const Emitter& emit) override {
    if (remaining_ == 0) return;
    auto d = matcher_.decode(frame, config_.roi);
    RegionMatcher::emit_depths(d, frame, emit);
    std::optional<Classification> c;
    view_ = view_target(d.valid, d.pixels, d.median_mm, config_.min_valid_fraction, table_->bins());
    const bool filled = view_.state != "none";
    if (view_.state == "out_of_range") {
      ++out_of_range_frames_;
      out_of_range_why_ = view_.reason;
    }
    if (filled) {
      frame_matcher_.reset();
      frame_matcher_.accumulate(d);
      c = frame_matcher_.classify();
    }
    // The corrected depth is corrected for this frame's own label.
    const std::int64_t material = c && !frame_matcher_.unknown(*c) ? std::int64_t{c->best().index} : -1;
    RegionMatcher::emit_corrected(d, frame, emit, *table_, [material](std::size_t) { return material; });
    if (c) frames_.push_back({table_->material_id(c->best().index), std::move(d)});
    if (--remaining_ > 0) return;
    emit.label(burst_label(frame));
    frames_.clear();
    out_of_range_frames_ = 0;
  }

  std::optional<TargetView> target() const override { return view_; }

  void reset() override {
    matcher_.reset();
    frames_.clear();
    remaining_ = 0;
    out_of_range_frames_ = 0;
  }

 private:
  struct Frame {
    // This frame's own Eq. (12) best match, as its material (ExemplarTable::material_id): two
    // exemplars of one material (cork@0, cork@30) are one vote, not a mixed burst.
    std::uint32_t material;
    RegionMatcher::Decoded decoded;
  };

  protocol::LabelEvent burst_label(const RawFrame& last) {
    protocol::LabelEvent e;
    e.state = "no_target";
    // The majority of the frames' own labels (materials).
    std::map<std::uint32_t, std::size_t> votes;
    for (const auto& f : frames_) ++votes[f.material];
    std::uint32_t majority = 0;
    std::size_t most = 0;
    for (const auto& [label, n] : votes)
      if (n > most) most = n, majority = label;
    if (!frames_.empty()) {
      const bool strict = 2 * most > frames_.size();
      matcher_.reset();
      for (const auto& f : frames_)
        if (!strict || f.material == majority) matcher_.accumulate(f.decoded);
      if (const auto c = matcher_.classify()) {
        e = matcher_.label_event(*c, config_.top_k);
        e.state = matcher_.unknown(*c)                                         ? "unknown"
                  : strict && table_->material_id(c->best().index) == majority ? "final"
                                                                               : "mixed";
        matcher_.learn_sweep();  // (after its label: a sweep teaches the ones after it)
      }
    }
    const bool out_of_range = e.state == "no_target" && out_of_range_frames_ > 0;
    if (out_of_range) {
      // The item was there, at a depth the table's bins miss: say so (the line rejects it: out_of_range).
      e.state = "out_of_range";
      if (!was_out_of_range_)  // (once until a burst is labelled again: not a line per item)
        logger(LogCategory::kProfile).warn("sorting: trigger {}: {}", trigger_, out_of_range_why_);
    }
    was_out_of_range_ = out_of_range;
    e.frame = last.sequence;
    e.timestamp_ns = last.arrival_ns;
    e.profile = "sorting";
    e.trigger = trigger_;
    e.truth = region_truth(last, config_.roi);
    e.simulated = last.simulated;
    return e;
  }

  ProfileConfig config_;
  std::shared_ptr<const ExemplarTable> table_;
  RegionMatcher matcher_, frame_matcher_;
  std::vector<Frame> frames_;
  int remaining_ = 0;
  std::uint64_t trigger_ = 0;
  TargetView view_;
  std::size_t out_of_range_frames_ = 0;  // of this burst
  std::string out_of_range_why_;
  bool was_out_of_range_ = false;  // the last burst's label
};

}  // namespace

std::unique_ptr<Profile> make_sorting(const ProfileConfig& c, const std::shared_ptr<const ExemplarTable>& table) {
  return std::make_unique<SortingProfile>(c, table);
}

}  // namespace tofmat::daemon
