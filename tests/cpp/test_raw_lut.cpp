// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The Kinect v2's 11-bit sample code and its 16-bit value
// (shared/docs/kinect2-protocol.md 2.4): bit 10 the sign, the low 10 bits a
// companded magnitude, code 1024 the saturation marker 32767. The expected
// values are written out from the protocol document, never taken from the
// code under test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "tofmat/core/raw_lut.hpp"

namespace {

using tofmat::raw_code_nearest;
using tofmat::raw_code_value;

// The document's step s(c) between magnitude codes c and c + 1.
int doc_step(int c) { return c < 256 ? 1 : 1 << (c / 128 - 1); }

// Magnitudes by the document, c = 0..1023.
std::vector<int> doc_magnitudes() {
  std::vector<int> v(1024, 0);
  for (int c = 0; c < 1023; ++c) v[static_cast<std::size_t>(c + 1)] = v[static_cast<std::size_t>(c)] + doc_step(c);
  return v;
}

std::uint16_t code(int c) { return static_cast<std::uint16_t>(c); }

TEST(RawLut, DocumentedAnchorValues) {
  EXPECT_EQ(raw_code_value(0), 0);
  EXPECT_EQ(raw_code_value(1), 1);
  EXPECT_EQ(raw_code_value(255), 255);
  EXPECT_EQ(raw_code_value(256), 256);
  EXPECT_EQ(raw_code_value(257), 258);  // first step of 2
  EXPECT_EQ(raw_code_value(384), 512);
  EXPECT_EQ(raw_code_value(512), 1024);
  EXPECT_EQ(raw_code_value(640), 2048);
  EXPECT_EQ(raw_code_value(768), 4096);
  EXPECT_EQ(raw_code_value(896), 8192);
  EXPECT_EQ(raw_code_value(1023), 16320);
  EXPECT_EQ(tofmat::kRawMaxMagnitude, 16320);
}

TEST(RawLut, EveryPositiveCodeFollowsTheDocumentedSteps) {
  const auto v = doc_magnitudes();
  ASSERT_EQ(v[1023], 16320);  // the document's own check of the recurrence
  for (int c = 0; c < 1024; ++c) {
    EXPECT_EQ(raw_code_value(code(c)), v[static_cast<std::size_t>(c)]) << "code " << c;
    if (c > 0) {
      EXPECT_EQ(raw_code_value(code(c)) - raw_code_value(code(c - 1)), doc_step(c - 1)) << "code " << c;
    }
  }
}

TEST(RawLut, NegativeCodesAndTheSaturationMarker) {
  EXPECT_EQ(raw_code_value(1024), 32767);  // "minus zero" is the saturation marker
  EXPECT_EQ(raw_code_value(tofmat::kRawSaturationCode), tofmat::kRawSaturated);
  const auto v = doc_magnitudes();
  for (int c = 1; c < 1024; ++c) {
    EXPECT_EQ(raw_code_value(code(1024 + c)), -v[static_cast<std::size_t>(c)]) << "code " << 1024 + c;
  }
  EXPECT_EQ(raw_code_value(1025), -1);
  EXPECT_EQ(raw_code_value(2047), -16320);
}

TEST(RawLut, OnlyTheLowElevenBitsAreUsed) {
  for (int c = 0; c < 2048; ++c) {
    EXPECT_EQ(raw_code_value(code(c | 0x800)), raw_code_value(code(c))) << c;
    EXPECT_EQ(raw_code_value(code(c | 0xF800)), raw_code_value(code(c))) << c;
  }
}

TEST(RawLut, NearestRoundTripsEveryCode) {
  for (int c = 0; c < 2048; ++c) {
    if (c == 1024) continue;  // the marker is not a value
    const double v = raw_code_value(code(c));
    EXPECT_EQ(raw_code_nearest(v), c) << "value " << v;
  }
}

// For values between codes (every quarter count across the whole range) the
// chosen code's value is at least as near as either neighbour's. Ties may go
// either way; the distance must be the minimum.
TEST(RawLut, NearestIsNearest) {
  std::vector<int> signed_values;  // every value the code can carry, sorted
  for (int c = 0; c < 2048; ++c) {
    if (c != 1024) signed_values.push_back(raw_code_value(code(c)));
  }
  std::sort(signed_values.begin(), signed_values.end());
  for (int q = -4 * 16320; q <= 4 * 16320; ++q) {
    const double x = q * 0.25;
    const auto it = std::lower_bound(signed_values.begin(), signed_values.end(), x);
    double best = std::numeric_limits<double>::infinity();
    if (it != signed_values.end()) best = std::min(best, *it - x);
    if (it != signed_values.begin()) best = std::min(best, x - *(it - 1));
    const std::uint16_t c = raw_code_nearest(x);
    ASSERT_NE(c, tofmat::kRawSaturationCode) << x;
    ASSERT_LT(c, 2048) << x;
    ASSERT_EQ(std::fabs(raw_code_value(c) - x), best) << "value " << x << " -> code " << c;
    // Same sign as the value (zero excepted).
    if (raw_code_value(c) != 0) {
      ASSERT_EQ(raw_code_value(c) < 0, x < 0) << x;
    }
  }
}

TEST(RawLut, NearestMidpointsOfWideSteps) {
  // Between 8192 (code 896) and 8256 (code 897): 8223 is nearer 8192, 8225 nearer 8256.
  EXPECT_EQ(raw_code_value(raw_code_nearest(8223.0)), 8192);
  EXPECT_EQ(raw_code_value(raw_code_nearest(8225.0)), 8256);
  EXPECT_EQ(raw_code_value(raw_code_nearest(-8225.0)), -8256);
  EXPECT_EQ(raw_code_value(raw_code_nearest(16300.0)), 16320);
  EXPECT_EQ(raw_code_value(raw_code_nearest(16200.0)), 16192);  // 16256 - 64
}

TEST(RawLut, NearestClampsBeyondTheRangeAndNeverGivesTheMarker) {
  EXPECT_EQ(raw_code_nearest(16320.0), 1023);
  EXPECT_EQ(raw_code_nearest(16321.0), 1023);
  EXPECT_EQ(raw_code_nearest(1e300), 1023);
  EXPECT_EQ(raw_code_nearest(std::numeric_limits<double>::infinity()), 1023);
  EXPECT_EQ(raw_code_nearest(-16321.0), 2047);
  EXPECT_EQ(raw_code_nearest(-1e300), 2047);
  EXPECT_EQ(raw_code_nearest(-std::numeric_limits<double>::infinity()), 2047);
  // Zero and values rounding to zero take the +0 code, never the "-0" marker.
  EXPECT_EQ(raw_code_nearest(0.0), 0);
  EXPECT_EQ(raw_code_nearest(-0.0), 0);
  EXPECT_EQ(raw_code_nearest(-0.49), 0);
  EXPECT_EQ(raw_code_nearest(0.49), 0);
  EXPECT_EQ(raw_code_nearest(-1e-300), 0);
  // NaN must still give a real code (not the marker, not out of range).
  const std::uint16_t n = raw_code_nearest(std::numeric_limits<double>::quiet_NaN());
  EXPECT_NE(n, tofmat::kRawSaturationCode);
  EXPECT_LT(n, 2048);
}

}  // namespace

TEST(RawLut, MagnitudeNearestMatchesTheCodeSearch) {
  // Every quarter count from 0 to the top (ties included: halves of odd steps
  // and midpoints of wide steps land on quarters), plus values just either side.
  for (int q = 0; q <= 4 * tofmat::kRawMaxMagnitude; ++q) {
    for (double v : {q / 4.0, std::nextafter(q / 4.0, 0.0), std::nextafter(q / 4.0, 1e9)}) {
      if (v < 0.0 || v > tofmat::kRawMaxMagnitude) continue;
      ASSERT_EQ(tofmat::raw_magnitude_nearest(v), tofmat::raw_code_value(tofmat::raw_code_nearest(v))) << v;
    }
  }
}

TEST(RawLut, QuantiseRowMatchesTheCodeSearchAwayFromTies) {
  // Every quarter count of both signs (exact in float, ties included), and
  // values 0.01 either side: the row quantiser rounds through float, which
  // moves a sample by at most 1e-3 counts, so only samples that close to a tie
  // may go the other way.
  std::vector<double> in;
  for (int q = 0; q <= 4 * tofmat::kRawMaxMagnitude; ++q) {
    for (double v : {q / 4.0, q / 4.0 - 0.01, q / 4.0 + 0.01}) {
      if (v < 0.0 || v > tofmat::kRawMaxMagnitude) continue;
      in.push_back(v);
      in.push_back(-v);
    }
  }
  std::vector<std::int16_t> out(in.size(), 0);
  tofmat::raw_quantise(in.data(), in.size(), 32000.0, out.data());
  for (std::size_t k = 0; k < in.size(); ++k) {
    ASSERT_EQ(out[k], raw_code_value(raw_code_nearest(in[k]))) << in[k];
  }
}

TEST(RawLut, QuantiseRowSaturatesClampsAndRejectsNaN) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<double> in{0.0, -0.0, -0.4, 16320.0, 17000.0, -17000.0, 20000.0, 20000.5, -30000.0, nan, inf, -inf};
  std::vector<std::int16_t> out(in.size(), 1);
  // Saturation level 20000 counts: beyond the top code the magnitude clamps to
  // 16320 until the level, then the marker (also for NaN and infinities).
  tofmat::raw_quantise(in.data(), in.size(), 20000.0, out.data());
  const std::vector<std::int16_t> want{0, 0, 0, 16320, 16320, -16320, 16320, 32767, 32767, 32767, 32767, 32767};
  EXPECT_EQ(out, want);
  // A lower level (a profile's saturation below the code's top).
  std::vector<std::int16_t> low(3, 1);
  const std::vector<double> in_low{999.0, 1000.5, -1001.0};
  tofmat::raw_quantise(in_low.data(), in_low.size(), 1000.0, low.data());
  EXPECT_EQ(low, (std::vector<std::int16_t>{1000, 32767, 32767}));
}
