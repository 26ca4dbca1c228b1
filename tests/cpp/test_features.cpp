// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The paper's features (Sec. 4): Eq. (1) phase to depth, the unambiguous
// range, Eqs. (8), (10), (11), and the table rows built from per-frequency depths.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/features.hpp"

namespace {

using tofmat::depth_from_phase_mm;
using tofmat::unambiguous_range_mm;

const double kPi = 3.14159265358979323846;
const double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(Features, SpeedOfLightIsTheDatabaseConvention) {
  EXPECT_EQ(tofmat::kSpeedOfLightMmPerNs, 300.0);  // database README: c = 300 mm/ns
}

TEST(Features, UnambiguousRange) {
  // c / (2 f): 300 mm/ns / (2 * 0.12 /ns) = 1250 mm.
  EXPECT_DOUBLE_EQ(unambiguous_range_mm(120.0), 1250.0);
  EXPECT_DOUBLE_EQ(unambiguous_range_mm(80.0), 1875.0);
  EXPECT_DOUBLE_EQ(unambiguous_range_mm(16.0), 9375.0);
}

TEST(Features, DepthFromPhaseEq1) {
  EXPECT_EQ(depth_from_phase_mm(0.0, 120.0), 0.0);
  EXPECT_DOUBLE_EQ(depth_from_phase_mm(kPi, 120.0), 625.0);
  EXPECT_DOUBLE_EQ(depth_from_phase_mm(kPi / 2, 80.0), 1875.0 / 4);
  EXPECT_DOUBLE_EQ(depth_from_phase_mm(1.0, 16.0), 300.0 * 1.0 / (4 * kPi * 0.016));  // d = c phase / (4 pi f)
}

TEST(Features, DepthFromPhaseWraps) {
  const double two_pi = 2 * kPi;
  const double below = std::nextafter(two_pi, 0.0);
  const double d = depth_from_phase_mm(below, 120.0);
  EXPECT_LT(d, 1250.0);
  EXPECT_NEAR(d, 1250.0, 1e-9);
  EXPECT_EQ(depth_from_phase_mm(two_pi, 120.0), 0.0);  // a full turn is distance 0
  EXPECT_NEAR(depth_from_phase_mm(two_pi + kPi, 120.0), 625.0, 1e-9);
  EXPECT_NEAR(depth_from_phase_mm(-kPi / 2, 120.0), 1250.0 * 0.75, 1e-9);
  EXPECT_NEAR(depth_from_phase_mm(-5 * kPi / 2, 120.0), 1250.0 * 0.75, 1e-9);
  // A tiny negative phase wraps to just below 2 pi, which rounds to 2 pi: must come back as 0, never 1250.
  const double tiny = depth_from_phase_mm(-1e-300, 120.0);
  EXPECT_GE(tiny, 0.0);
  EXPECT_LT(tiny, 1250.0);
  for (double p : {-100.0, -1e-9, 1e-9, 6.28, 100.0, 1e6}) {
    const double x = depth_from_phase_mm(p, 80.0);
    EXPECT_GE(x, 0.0) << p;
    EXPECT_LT(x, 1875.0) << p;
  }
}

TEST(Features, DepthFromPhaseNonFinite) {
  EXPECT_TRUE(std::isnan(depth_from_phase_mm(kNaN, 120.0)));
  EXPECT_TRUE(std::isnan(depth_from_phase_mm(std::numeric_limits<double>::infinity(), 120.0)));
  EXPECT_TRUE(std::isnan(depth_from_phase_mm(1.0, 0.0)));
  EXPECT_TRUE(std::isnan(depth_from_phase_mm(1.0, -16.0)));
  EXPECT_TRUE(std::isnan(depth_from_phase_mm(1.0, kNaN)));
}

TEST(Features, DistortionEquations) {
  EXPECT_DOUBLE_EQ(tofmat::absolute_distortion_mm(800.0, 812.5), -12.5);             // Eq. (8): d_true - d(f)
  EXPECT_DOUBLE_EQ(tofmat::relative_distortion_mm(800.0, 812.5), -12.5);             // Eq. (10): d(ref) - d(f)
  EXPECT_DOUBLE_EQ(tofmat::depth_relative_distortion_mm(700.0, 750.0, 49.0), -1.0);  // Eq. (11)
  EXPECT_DOUBLE_EQ(tofmat::depth_relative_distortion_mm(700.0, 650.0, -50.0), 0.0);
}

TEST(Features, FrequencyFeaturesUseTheDatabaseSign) {
  const auto rows = tofmat::kinect2_database_rows();
  // Raw sub-image order of the Kinect v2: 80, 16, 120 MHz.
  const double freqs[3] = {80.0, 16.0, 120.0};
  const double depths[3] = {805.0, 890.0, 800.0};
  float out[2];
  tofmat::frequency_features(rows, freqs, depths, 3, out);
  EXPECT_FLOAT_EQ(out[0], 90.0f);  // d(16) - d(120): positive, like row 0 of the database
  EXPECT_FLOAT_EQ(out[1], 5.0f);   // d(80) - d(120)
}

TEST(Features, FrequencyFeaturesMissingGivesNaN) {
  const auto rows = tofmat::kinect2_database_rows();
  const double freqs[2] = {16.0, 120.0};  // no 80 MHz
  const double depths[2] = {890.0, 800.0};
  float out[2];
  tofmat::frequency_features(rows, freqs, depths, 2, out);
  EXPECT_FLOAT_EQ(out[0], 90.0f);
  EXPECT_TRUE(std::isnan(out[1]));

  const double with_nan[3] = {kNaN, 890.0, 800.0};
  const double all3[3] = {80.0, 16.0, 120.0};
  tofmat::frequency_features(rows, all3, with_nan, 3, out);
  EXPECT_FLOAT_EQ(out[0], 90.0f);
  EXPECT_TRUE(std::isnan(out[1]));

  const double no_ref[2] = {80.0, 16.0};
  tofmat::frequency_features(rows, no_ref, depths, 2, out);
  EXPECT_TRUE(std::isnan(out[0]));
  EXPECT_TRUE(std::isnan(out[1]));
}

TEST(Features, FrequencyFeaturesRejectUnknownRows) {
  const double freqs[3] = {80.0, 16.0, 120.0};
  const double depths[3] = {1, 2, 3};
  float out[2];
  EXPECT_THROW(tofmat::frequency_features({{0, 120}}, freqs, depths, 3, out), std::invalid_argument);
  EXPECT_THROW(tofmat::frequency_features({{16, 120}, {80, 0}}, freqs, depths, 3, out), std::invalid_argument);
}

// Eq. (1) and the feature rows together: phases that encode a known depth
// give back the depth differences, including the wrap of the 120 MHz phase.
TEST(Features, PhasesToFeatures) {
  auto features_at = [](double true_depth, float* out) {
    double depths[3];
    for (int i = 0; i < 3; ++i) {
      const double f = tofmat::kKinect2FrequenciesMhz[i];
      const double phase = 4 * kPi * (f * 1e-3) * true_depth / 300.0;  // inverse of Eq. (1), unwrapped
      depths[i] = depth_from_phase_mm(phase, f);
    }
    tofmat::frequency_features(tofmat::kinect2_database_rows(), tofmat::kKinect2FrequenciesMhz, depths, 3, out);
  };
  float out[2];
  features_at(1000.0, out);  // inside every unambiguous range (1250, 1875, 9375 mm): no wrap
  EXPECT_NEAR(out[0], 0.0f, 1e-6f);
  EXPECT_NEAR(out[1], 0.0f, 1e-6f);
  features_at(1500.0, out);  // 120 MHz wraps to 250 mm, the others do not
  EXPECT_NEAR(out[0], 1250.0f, 1e-3f);
  EXPECT_NEAR(out[1], 1250.0f, 1e-3f);
}

}  // namespace
