// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The segmentation's integer box mean (BoxMeanFilter) against the float
// reference: OpenCV's box filter in double precision over the features in mm
// and the valid mask, divided. The written error budget (docs/numerics.md):
// each feature rounded to Q8 is off by at most 1/512 mm, so is their mean,
// and the mean's own rounding to Q16 adds at most 1/65536 mm.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/frame_smoothing.hpp"

namespace {

TEST(BoxMeanReference, WithinTheBudgetOfOpenCVsDoubleBoxFilter) {
  constexpr int w = 512, h = 424;
  constexpr double kBudgetMm = 1.0 / 512.0 + 1.0 / 65536.0;
  std::mt19937 rng(2017);
  std::normal_distribution<double> noise(0.0, 40.0);  // mm around a material's smooth curve
  std::bernoulli_distribution dead(0.05);
  std::vector<std::int32_t> f0(w * h), f1(w * h);
  std::vector<std::uint8_t> flags(w * h);
  cv::Mat m0(h, w, CV_64F), m1(h, w, CV_64F), valid(h, w, CV_64F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const auto i = static_cast<std::size_t>(y * w + x);
      const bool ok = !dead(rng);
      flags[i] = ok ? 0 : 4;
      const double a = 300.0 * std::sin(x / 40.0) + noise(rng), b = -2000.0 + 3.0 * y + noise(rng);
      f0[i] = ok ? static_cast<std::int32_t>(std::lround(a * 65536.0)) : tofmat::kFixedInvalid;
      f1[i] = ok ? static_cast<std::int32_t>(std::lround(b * 65536.0)) : tofmat::kFixedInvalid;
      m0.at<double>(y, x) = ok ? f0[i] / 65536.0 : 0.0;
      m1.at<double>(y, x) = ok ? f1[i] / 65536.0 : 0.0;
      valid.at<double>(y, x) = ok ? 1.0 : 0.0;
    }
  for (int side : {3, 9, 15}) {
    const cv::Size k(side, side);
    cv::Mat s0, s1, n;
    cv::boxFilter(m0, s0, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(m1, s1, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(valid, n, -1, k, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    std::vector<std::int32_t> o0(w * h), o1(w * h);
    tofmat::BoxMeanFilter box(w, h, side);
    box.apply(f0.data(), f1.data(), flags.data(), 0, h, o0.data(), o1.data());
    double worst = 0.0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const auto i = static_cast<std::size_t>(y * w + x);
        if (flags[i] != 0) continue;
        const double c = n.at<double>(y, x);
        worst = std::max(worst, std::abs(o0[i] / 65536.0 - s0.at<double>(y, x) / c));
        worst = std::max(worst, std::abs(o1[i] / 65536.0 - s1.at<double>(y, x) / c));
      }
    EXPECT_LE(worst, kBudgetMm) << "side " << side;
    EXPECT_GT(worst, 0.0) << "side " << side;  // (the Q8 rounding is there: the comparison is live)
  }
}

}  // namespace
