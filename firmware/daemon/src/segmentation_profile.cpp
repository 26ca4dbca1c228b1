// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The segmentation profile: a scene of several materials at once, each pixel
// labelled from one position (m = 1: the two Eq. (10) features at the bin of
// the pixel's own depth) among a short candidate list. The features are
// averaged over a small window of valid pixels first (a single pixel's
// features are a few mm noisy) and the label map is cleaned with a majority
// filter, both in integers (frame_smoothing.hpp); with --accumulate, over the
// pixel's last frames too (frame_accumulator.hpp), and each surface of steady
// depth takes its majority label (region_vote.hpp). Runs on the fixed-point
// decode and the per-pixel classifier (PixelClassifier: AVX2, NEON or
// scalar, the same labels). The frame is split into bands of rows over the
// configured threads; every step gives the same values whatever the split.
#include <algorithm>
#include <array>

#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/frame_accumulator.hpp"
#include "tofmat/core/frame_smoothing.hpp"
#include "tofmat/core/pixel_classifier.hpp"
#include "tofmat/core/region_vote.hpp"
#include "tofmat/daemon/band_workers.hpp"
#include "tofmat/daemon/region_matcher.hpp"

namespace tofmat::daemon {
namespace {

static_assert(PixelClassifier::kUnclassified == protocol::kNoLabel, "the label map's 'none' is the classifier's");

std::array<std::uint8_t, protocol::kNoLabel + 1> identity_labels() {
  std::array<std::uint8_t, protocol::kNoLabel + 1> a{};
  for (std::size_t i = 0; i < a.size(); ++i) a[i] = static_cast<std::uint8_t>(i);
  return a;
}

class SegmentationProfile : public Profile {
 public:
  SegmentationProfile(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table)
      : config_(c),
        table_(std::move(table)),
        compact_(*table_, candidate_indices(*table_, c.candidates)),
        pixels_(compact_, table_->bins()),
        thresholds_(fixed_thresholds(DecodeOptions{})),
        workers_(std::min(BandWorkers::bands_for(c.threads), kHeight)),
        mean_{std::vector<std::int32_t>(kPixels), std::vector<std::int32_t>(kPixels)},
        unclean_(kPixels),
        accumulator_(c.accumulate > 1 ? kPixels : 0, c.accumulate, kAccumulateJumpQ8),  // (no memory unless used)
        vote_(kWidth, kHeight, kRegionStepQ8, kRegionMinPixels, static_cast<int>(compact_.candidates().size())) {
    if (c.accumulate > 1)
      for (auto& plane : accumulated_) plane.resize(kPixels);
    // A label per candidate material: a table's exemplars of one material (cork@0, cork@30) are one
    // label, so the smoothing majority and the region vote count them together (apart, a region
    // split between two exemplars of cork could lose to one of another material).
    for (std::size_t pos = 0; pos < compact_.candidates().size(); ++pos) {
      const auto& material = table_->material_of(compact_.candidates()[pos]);
      if (std::find(names_.begin(), names_.end(), material) == names_.end()) names_.push_back(material);
      const auto id = std::find(names_.begin(), names_.end(), material) - names_.begin();
      to_material_[pos] = static_cast<std::uint8_t>(id);
      remap_ = remap_ || to_material_[pos] != pos;
    }
    for (int b = 0; b < workers_.bands() && config_.smooth > 1; ++b) {
      box_.emplace_back(kWidth, kHeight, config_.smooth);
      majority_.emplace_back(kWidth, kHeight, config_.smooth, static_cast<int>(names_.size()));
    }
  }

  std::optional<PixelRegion> input_region() const override { return PixelRegion{0, 0, kWidth, kHeight}; }

  void process(const RawFrame& frame, const Emitter& emit) override {
    protocol::LabelMapEvent e;
    e.labels.resize(kPixels);
    label(frame, e.labels.data());
    e.frame = frame.sequence;
    e.timestamp_ns = frame.arrival_ns;
    e.width = kWidth;
    e.height = kHeight;
    e.materials = names_;
    if (frame.truth) e.truth_accuracy = accuracy(*frame.truth, e.labels);
    e.simulated = frame.simulated;
    RegionMatcher::Decoded d;
    d.region = PixelRegion{0, 0, kWidth, kHeight};
    d.pixels = kPixels;
    d.frame = std::move(frame_);  // lent to the depth events, taken back after
    RegionMatcher::emit_depths(d, frame, emit);
    // Each pixel corrected for its own label (a candidate's index -> the table's).
    const auto& candidates = compact_.candidates();
    RegionMatcher::emit_corrected(d, frame, emit, *table_, [&](std::size_t i) {
      const std::uint8_t k = e.labels[i];
      return k < candidates.size() ? std::int64_t{candidates[k]} : std::int64_t{-1};
    });
    frame_ = std::move(std::get<FixedDecodedFrame>(d.frame));
    emit.label_map(e);
  }

  void reset() override { accumulator_.reset(); }

 private:
  // Rows [y0, y1) of band b.
  std::pair<int, int> rows(int b) const {
    return {b * kHeight / workers_.bands(), (b + 1) * kHeight / workers_.bands()};
  }
  static std::size_t at(int y) { return static_cast<std::size_t>(y) * static_cast<std::size_t>(kWidth); }

  // Decode (into the same buffers every frame: a fresh full-frame decode
  // costs more in page faults than in arithmetic), features smoothed, each
  // pixel classified, the label map cleaned: each step over every band
  // before the next, since the windows reach into the neighbouring bands.
  void label(const RawFrame& frame, std::uint8_t* labels) {
    size_fixed_frame(frame_, kPixels);  // (no allocation once sized; restores a frame an exception left lent)
    const bool accumulate = config_.accumulate > 1;
    workers_.run([&](int b) {
      const auto [y0, y1] = rows(b);
      decode_pixels_fixed(frame.raw.data(), frame.calibration->fixed_tables, at(y0), at(y1) - at(y0), thresholds_,
                          planes_of(frame_, at(y0)));
      // Each pixel's means over its last frames (its own rows only: no window reaches across bands).
      if (accumulate)
        accumulator_.add(frame_.combined_q8.data(), frame_.flags.data(), frame_.features_q16[0].data(),
                         frame_.features_q16[1].data(), at(y0), at(y1), accumulated_[0].data(), accumulated_[1].data(),
                         accumulated_[2].data());
    });
    const bool smooth = config_.smooth > 1;
    workers_.run([&](int b) {
      const auto [y0, y1] = rows(b);
      // The depth that picks a pixel's bin and its features: this frame's, or the means over frames.
      const std::int32_t* depth = accumulate ? accumulated_[0].data() : frame_.combined_q8.data();
      const std::int32_t* f0 = accumulate ? accumulated_[1].data() : frame_.features_q16[0].data();
      const std::int32_t* f1 = accumulate ? accumulated_[2].data() : frame_.features_q16[1].data();
      if (smooth) {
        box_[static_cast<std::size_t>(b)].apply(f0, f1, frame_.flags.data(), y0, y1, mean_[0].data(), mean_[1].data());
        f0 = mean_[0].data();
        f1 = mean_[1].data();
      }
      std::uint8_t* out = (smooth ? unclean_.data() : labels) + at(y0);
      pixels_.classify_range(depth + at(y0), frame_.flags.data() + at(y0), f0 + at(y0), f1 + at(y0), at(y1) - at(y0),
                             out);
      if (remap_)  // (candidate entries to materials; kNoLabel stays)
        for (std::size_t i = 0, n = at(y1) - at(y0); i < n; ++i) out[i] = to_material_[out[i]];
    });
    if (smooth) {
      workers_.run([&](int b) {
        const auto [y0, y1] = rows(b);
        majority_[static_cast<std::size_t>(b)].apply(unclean_.data(), y0, y1, labels);
      });
    }
    if (config_.region_vote) vote_.apply(frame_.combined_q8.data(), frame_.flags.data(), labels);
  }

 private:
  // Of the pixels that show a target, the fraction labelled with its material.
  double accuracy(const FrameTruth& t, const std::vector<std::uint8_t>& labels) const {
    // Each truth material's label (kNoLabel: not a candidate, never right),
    // once a frame: then an integer comparison per pixel.
    // Each label's truth material (-1: none), once a frame: then an integer
    // comparison per pixel (a table of exemplars gives one material several labels).
    std::vector<std::int32_t> truth_of(protocol::kNoLabel + 1, -1);
    for (std::size_t k = 0; k < names_.size(); ++k)
      for (std::size_t m = 0; m < t.materials.size(); ++m)
        if (names_[k] == t.materials[m]) truth_of[k] = static_cast<std::int32_t>(m);
    std::size_t total = 0, right = 0;
    for (std::size_t i = 0; i < kPixels; ++i) {
      const auto m = static_cast<std::size_t>(t.target[i]);  // (-1 -> beyond every index)
      if (m >= t.materials.size()) continue;
      ++total;
      right += truth_of[labels[i]] == static_cast<std::int32_t>(m);
    }
    return total ? static_cast<double>(right) / static_cast<double>(total) : 0.0;
  }

  ProfileConfig config_;
  std::shared_ptr<const ExemplarTable> table_;
  CompactTable compact_;
  PixelClassifier pixels_;
  FixedThresholds thresholds_;
  BandWorkers workers_;
  FixedDecodedFrame frame_;
  std::vector<BoxMeanFilter> box_;                 // per band
  std::vector<MajorityFilter> majority_;           // per band
  std::array<std::vector<std::int32_t>, 2> mean_;  // the smoothed features (Q16 mm)
  // Region voting: neighbours at most 10 mm apart in depth are one surface
  // (a plane at 60 degrees to the rays steps about 6 mm a pixel at 1.2 m);
  // a surface of 100 pixels or more votes.
  static constexpr std::int32_t kRegionStepQ8 = 10 * 256;
  static constexpr std::size_t kRegionMinPixels = 100;
  // A pixel's depth this far from its mean over frames starts its accumulation over.
  static constexpr std::int32_t kAccumulateJumpQ8 = 16 * 256;
  std::vector<std::uint8_t> unclean_;  // the labels before the majority filter
  FrameAccumulator accumulator_;
  // Its means (depth Q8, two features Q16): sized and written only with --accumulate above 1.
  std::array<std::vector<std::int32_t>, 3> accumulated_;
  RegionVote vote_;
  std::vector<std::string> names_;  // the label map's labels: the candidates' materials
  // Each candidate entry's label (its position in candidates()) -> its material's in names_; an
  // identity (remap_ false) for a table of one entry a material.
  std::array<std::uint8_t, protocol::kNoLabel + 1> to_material_ = identity_labels();
  bool remap_ = false;
};

}  // namespace

std::unique_ptr<Profile> make_segmentation(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table) {
  return std::make_unique<SegmentationProfile>(c, std::move(table));
}

}  // namespace tofmat::daemon
