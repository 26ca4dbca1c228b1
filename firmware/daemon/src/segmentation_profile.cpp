// The segmentation profile: a scene of several materials at once, each pixel
// labelled from one position (m = 1: the two Eq. (10) features at the bin of
// the pixel's own depth) among a short candidate list. The features are
// averaged over a small window of valid pixels first (a single pixel's
// features are a few mm noisy) and the label map is cleaned with a median
// filter (OpenCV). Runs on the fixed-point decode and the per-pixel
// classifier (PixelClassifier: AVX2 or scalar, the same labels).
#include <opencv2/imgproc.hpp>

#include <array>
#include <cmath>

#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/fixed_depth_bins.hpp"
#include "tofmat/core/pixel_classifier.hpp"
#include "tofmat/daemon/region_matcher.hpp"

namespace tofmat::daemon {
namespace {

static_assert(PixelClassifier::kUnclassified == protocol::kNoLabel, "the label map's 'none' is the classifier's");

class SegmentationProfile : public Profile {
 public:
  SegmentationProfile(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table)
      : config_(c),
        table_(std::move(table)),
        compact_(*table_, candidate_indices(*table_, c.candidates)),
        pixels_(compact_, table_->bins()),
        bin_(kPixels),
        q16_{std::vector<std::int32_t>(kPixels), std::vector<std::int32_t>(kPixels)},
        f0_(kHeight, kWidth, CV_32F),
        f1_(kHeight, kWidth, CV_32F),
        valid_(kHeight, kWidth, CV_32F) {
    for (auto k : compact_.candidates()) names_.push_back(table_->materials()[k]);
  }

  std::optional<PixelRegion> input_region() const override { return PixelRegion{0, 0, kWidth, kHeight}; }

  void process(const RawFrame& frame, const Emitter& emit) override {
    // Into the same buffers every frame (a fresh full-frame decode costs more
    // in page faults than in arithmetic).
    decode_frame_fixed(frame.raw.data(), frame.calibration->fixed_tables, frame_);
    protocol::LabelMapEvent e;
    e.labels.resize(kPixels);
    if (config_.smooth > 1) {
      smooth_features();
      pixels_.classify(bin_.data(), q16_[0].data(), q16_[1].data(), kPixels, e.labels.data());
      cv::Mat labels(kHeight, kWidth, CV_8U, e.labels.data());  // (a view: the filter writes through)
      cv::medianBlur(labels.clone(), labels, config_.smooth);
    } else {
      pixels_.classify(frame_, e.labels.data());
    }
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
    frame_ = std::move(std::get<FixedDecodedFrame>(d.frame));
    emit.label_map(e);
  }

  void reset() override {}

 private:
  // The features averaged over a smooth x smooth window of valid pixels
  // (OpenCV box filters, in place in planes allocated once), back in Q16 mm,
  // and each pixel's bin (-1 where the pixel is invalid or out of the bins).
  void smooth_features() {
    cv::Mat& f0 = f0_;
    cv::Mat& f1 = f1_;
    cv::Mat& valid = valid_;
    for (std::size_t i = 0; i < kPixels; ++i) {
      const bool ok = frame_.flags[i] == 0;
      const int at = static_cast<int>(i);
      f0.at<float>(at) = ok ? static_cast<float>(frame_.features_q16[0][i] / 65536.0) : 0.0f;
      f1.at<float>(at) = ok ? static_cast<float>(frame_.features_q16[1][i] / 65536.0) : 0.0f;
      valid.at<float>(at) = ok ? 1.0f : 0.0f;
    }
    const cv::Size k(config_.smooth, config_.smooth);
    cv::boxFilter(f0, f0, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(f1, f1, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(valid, valid, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    bin_indices(FixedKernel::kBest, frame_.combined_q8.data(), frame_.flags.data(), kPixels, pixels_.binning(),
                bin_.data());
    for (std::size_t i = 0; i < kPixels; ++i) {
      // (A pixel with a bin is valid, so its own window counts it: n >= 1.)
      if (bin_[i] < 0) continue;
      const int at = static_cast<int>(i);
      const float n = valid.at<float>(at);
      // |mean| <= the largest |feature| (9375 mm): Q16 fits int32.
      q16_[0][i] = static_cast<std::int32_t>(std::lround(static_cast<double>(f0.at<float>(at) / n) * 65536.0));
      q16_[1][i] = static_cast<std::int32_t>(std::lround(static_cast<double>(f1.at<float>(at) / n) * 65536.0));
    }
  }

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
  PixelClassifier pixels_;
  FixedDecodedFrame frame_;
  std::vector<std::int32_t> bin_;
  std::array<std::vector<std::int32_t>, 2> q16_;
  cv::Mat f0_, f1_, valid_;  // the smoothing's planes
  std::vector<std::string> names_;
};

}  // namespace

std::unique_ptr<Profile> make_segmentation(const ProfileConfig& c, std::shared_ptr<const ExemplarTable> table) {
  return std::make_unique<SegmentationProfile>(c, std::move(table));
}

}  // namespace tofmat::daemon
