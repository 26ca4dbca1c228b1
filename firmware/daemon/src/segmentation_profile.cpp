// The segmentation profile: a scene of several materials at once, each pixel
// labelled from one position (m = 1: the two Eq. (10) features at the bin of
// the pixel's own depth) among a short candidate list. The features are
// averaged over a small window of valid pixels first (a single pixel's
// features are a few mm noisy) and the label map is cleaned with a median
// filter (OpenCV). Runs on the fixed-point decode and the compact table.
#include <opencv2/imgproc.hpp>

#include <cmath>

#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/fixed_depth_bins.hpp"
#include "tofmat/daemon/region_matcher.hpp"

namespace tofmat::daemon {
namespace {

class SegmentationProfile : public Profile {
 public:
  SegmentationProfile(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table)
      : config_(c),
        table_(std::move(table)),
        compact_(*table_, candidate_indices(*table_, c.candidates)),
        binning_(FixedBinning::from(table_->bins())) {
    for (auto k : compact_.candidates()) names_.push_back(table_->materials()[k]);
  }

  void process(const RawFrame& frame, const Emitter& emit) override {
    RegionMatcher::Decoded d;
    d.region = PixelRegion{0, 0, kWidth, kHeight};
    auto f = decode_frame_fixed(frame.raw.data(), frame.calibration->fixed_tables);
    d.pixels = f.pixels;
    std::vector<std::int32_t> bin(kPixels);
    bin_indices_scalar(f.combined_q8.data(), f.flags.data(), kPixels, binning_, bin.data());

    cv::Mat f0(kHeight, kWidth, CV_32F), f1(kHeight, kWidth, CV_32F), valid(kHeight, kWidth, CV_32F);
    for (std::size_t i = 0; i < kPixels; ++i) {
      const bool ok = f.flags[i] == 0;
      f0.at<float>(static_cast<int>(i)) = ok ? static_cast<float>(f.features_q16[0][i] / 65536.0) : 0.0f;
      f1.at<float>(static_cast<int>(i)) = ok ? static_cast<float>(f.features_q16[1][i] / 65536.0) : 0.0f;
      valid.at<float>(static_cast<int>(i)) = ok ? 1.0f : 0.0f;
    }
    if (config_.smooth > 1) {
      const cv::Size k(config_.smooth, config_.smooth);
      cv::boxFilter(f0, f0, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
      cv::boxFilter(f1, f1, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
      cv::boxFilter(valid, valid, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    }

    cv::Mat labels(kHeight, kWidth, CV_8U, cv::Scalar(protocol::kNoLabel));
    const double inv_step = 1.0 / compact_.step_mm();
    const std::size_t padded = compact_.padded_bins();
    for (std::size_t i = 0; i < kPixels; ++i) {
      const float n = valid.at<float>(static_cast<int>(i));
      if (bin[i] < 0 || n < 0.5f) continue;
      const std::int32_t q[2] = {quantise_to_step(f0.at<float>(static_cast<int>(i)) / n, inv_step),
                                 quantise_to_step(f1.at<float>(static_cast<int>(i)) / n, inv_step)};
      // Eq. (12) with m = 1: at most two elements; ranks by exact comparison
      // of sum / count, ties to the lower candidate.
      std::int64_t best_sum = 0, best_count = 0;
      int best = -1;
      for (std::size_t k = 0; k < compact_.n_candidates(); ++k) {
        const std::int16_t* v = compact_.values(k);
        const std::uint8_t* m = compact_.validity(k);
        std::int64_t sum = 0, count = 0;
        for (std::size_t r = 0; r < 2; ++r) {
          const std::size_t e = r * padded + static_cast<std::size_t>(bin[i]);
          if (m && !(m[e / 8] >> (e % 8) & 1)) continue;
          const std::int64_t diff = q[r] - v[e];
          sum += diff * diff;
          ++count;
        }
        if (count > 0 && (best < 0 || sum * best_count < best_sum * count)) {
          best = static_cast<int>(k);
          best_sum = sum;
          best_count = count;
        }
      }
      if (best >= 0) labels.at<std::uint8_t>(static_cast<int>(i)) = static_cast<std::uint8_t>(best);
    }
    if (config_.smooth > 1) cv::medianBlur(labels, labels, config_.smooth);

    protocol::LabelMapEvent e;
    e.frame = frame.sequence;
    e.timestamp_ns = frame.arrival_ns;
    e.width = kWidth;
    e.height = kHeight;
    e.materials = names_;
    e.labels.assign(labels.data, labels.data + kPixels);
    if (frame.truth) e.truth_accuracy = accuracy(*frame.truth, e.labels);
    d.frame = std::move(f);
    RegionMatcher::emit_depths(d, frame, emit);
    emit.label_map(e);
  }

  void reset() override {}

 private:
  // Of the pixels that show a target, the fraction labelled with its material.
  double accuracy(const FrameTruth& t, const std::vector<std::uint8_t>& labels) const {
    std::size_t total = 0, right = 0;
    for (std::size_t i = 0; i < kPixels; ++i) {
      if (t.target[i] < 0 || static_cast<std::size_t>(t.target[i]) >= t.materials.size()) continue;
      ++total;
      if (labels[i] != protocol::kNoLabel && names_[labels[i]] == t.materials[static_cast<std::size_t>(t.target[i])])
        ++right;
    }
    return total ? static_cast<double>(right) / static_cast<double>(total) : 0.0;
  }

  ProfileConfig config_;
  std::shared_ptr<const ExemplarTable> table_;
  CompactTable compact_;
  FixedBinning binning_;
  std::vector<std::string> names_;
};

}  // namespace

std::unique_ptr<Profile> make_segmentation(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table) {
  return std::make_unique<SegmentationProfile>(c, std::move(table));
}

}  // namespace tofmat::daemon
