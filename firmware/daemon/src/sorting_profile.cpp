// The sorting profile: an item on the belt passes the ROI; a trigger (the
// light barrier's GPIO line in a later issue, a socket command here) starts a
// burst of frames that are accumulated and classified once. Between bursts
// the frames are left alone: nothing is decoded.
#include "tofmat/daemon/region_matcher.hpp"

namespace tofmat::daemon {
namespace {

class SortingProfile : public Profile {
 public:
  SortingProfile(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table)
      : config_(c), matcher_(table, candidate_indices(*table, c.candidates), c.backend) {}

  std::uint64_t trigger(int burst) override {
    matcher_.reset();
    remaining_ = burst > 0 ? burst : config_.burst;
    used_ = 0;
    return ++trigger_;
  }

  std::optional<PixelRegion> input_region() const override {
    if (remaining_ == 0) return std::nullopt;  // between bursts: no pixel at all
    return config_.roi;
  }

  void process(const RawFrame& frame, const Emitter& emit) override {
    if (remaining_ == 0) return;
    const auto d = matcher_.decode(frame, config_.roi);
    RegionMatcher::emit_depths(d, frame, emit);
    if (static_cast<double>(d.valid) >= config_.min_valid_fraction * static_cast<double>(d.pixels)) {
      matcher_.accumulate(d);
      ++used_;
    }
    if (--remaining_ > 0) return;
    protocol::LabelEvent e;
    if (const auto c = used_ > 0 ? matcher_.classify() : std::nullopt) {
      e = matcher_.label_event(*c, config_.top_k);
      e.state = "final";
    } else {
      e.state = "no_target";
    }
    e.frame = frame.sequence;
    e.timestamp_ns = frame.arrival_ns;
    e.profile = "sorting";
    e.trigger = trigger_;
    e.truth = region_truth(frame, config_.roi);
    e.simulated = frame.simulated;
    emit.label(e);
  }

  void reset() override {
    matcher_.reset();
    remaining_ = 0;
  }

 private:
  ProfileConfig config_;
  RegionMatcher matcher_;
  int remaining_ = 0, used_ = 0;
  std::uint64_t trigger_ = 0;
};

}  // namespace

std::unique_ptr<Profile> make_sorting(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table) {
  return std::make_unique<SortingProfile>(c, std::move(table));
}

}  // namespace tofmat::daemon
