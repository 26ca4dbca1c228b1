// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FrameAccumulator (firmware/core frame_accumulator.hpp): per-pixel means over
// frames against a double reference, the noise they take away, starting over
// at a depth jump, an invalid pixel or a reset, the forgetting past `frames`,
// and the same values whatever the split into ranges.
#include "tofmat/core/frame_accumulator.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

namespace {

using tofmat::FrameAccumulator;

constexpr std::int32_t kJump = 16 * 256;  // 16 mm, Q8

struct Frame {
  std::vector<std::int32_t> depth, f0, f1;
  std::vector<std::uint8_t> flags;
  explicit Frame(std::size_t n) : depth(n), f0(n), f1(n), flags(n, 0) {}
};

struct Means {
  std::vector<std::int32_t> depth, f0, f1;
  explicit Means(std::size_t n) : depth(n), f0(n), f1(n) {}
};

void add(FrameAccumulator& a, const Frame& f, Means& m, std::size_t begin, std::size_t end) {
  a.add(f.depth.data(), f.flags.data(), f.f0.data(), f.f1.data(), begin, end, m.depth.data(), m.f0.data(), m.f1.data());
}

TEST(FrameAccumulator, MeansOfTheFramesSoFarRoundedToTheNearest) {
  FrameAccumulator a(1, 8, kJump);
  Frame f(1);
  Means m(1);
  const std::int32_t d[] = {230400, 230500, 230300, 230401, 230399};  // about 900 mm, within 1 mm
  const std::int32_t g[] = {-655360, 655360, 3, -7, 1000001};
  double sd = 0, sg = 0;
  for (int k = 0; k < 5; ++k) {
    f.depth[0] = d[k];
    f.f0[0] = g[k];
    f.f1[0] = -g[k];
    add(a, f, m, 0, 1);
    sd += d[k];
    sg += g[k];
    EXPECT_EQ(a.count(0), k + 1);
    EXPECT_LE(std::abs(m.depth[0] - sd / (k + 1)), 0.5);
    EXPECT_LE(std::abs(m.f0[0] - sg / (k + 1)), 0.5);
    EXPECT_EQ(m.f1[0], -m.f0[0]);  // (rounding is symmetric about zero)
  }
}

TEST(FrameAccumulator, OneFrameIsTheFramesOwnValues) {
  FrameAccumulator a(3, 1, kJump);
  Frame f(3);
  Means m(3);
  for (int k = 0; k < 4; ++k) {
    for (std::size_t i = 0; i < 3; ++i) f.depth[i] = 200000 + 1000 * k, f.f0[i] = k * 7 - 3, f.f1[i] = -k;
    add(a, f, m, 0, 3);
    EXPECT_EQ(m.depth, f.depth);
    EXPECT_EQ(m.f0, f.f0);
    EXPECT_EQ(m.f1, f.f1);
  }
}

TEST(FrameAccumulator, NoiseFallsAsOneOverTheRootOfTheFrames) {
  const std::size_t n = 4000;
  FrameAccumulator a(n, 16, kJump);
  Frame f(n);
  Means m(n);
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 3.0 * 65536.0);  // 3 mm of feature noise, Q16
  double rms1 = 0, rms16 = 0;
  for (int k = 0; k < 16; ++k) {
    for (std::size_t i = 0; i < n; ++i) {
      f.depth[i] = 256000;
      f.f0[i] = static_cast<std::int32_t>(std::lround(noise(rng)));
      f.f1[i] = 0;
    }
    add(a, f, m, 0, n);
    double s = 0;
    for (std::size_t i = 0; i < n; ++i) s += static_cast<double>(m.f0[i]) * m.f0[i];
    (k == 0 ? rms1 : rms16) = std::sqrt(s / n);
  }
  EXPECT_NEAR(rms16 / rms1, 0.25, 0.03);
}

TEST(FrameAccumulator, AJumpAnInvalidPixelOrAResetStartsOver) {
  FrameAccumulator a(2, 8, kJump);
  Frame f(2);
  Means m(2);
  for (int k = 0; k < 5; ++k) {
    f.depth = {230400, 230400};
    f.f0 = {100, 100};
    add(a, f, m, 0, 2);
  }
  EXPECT_EQ(a.count(0), 5);
  // Pixel 0: something 20 mm nearer (beyond 16); pixel 1: 15 mm (within: it is noise, or a slow move).
  f.depth = {230400 - 20 * 256, 230400 - 15 * 256};
  f.f0 = {900, 900};
  add(a, f, m, 0, 2);
  EXPECT_EQ(a.count(0), 1);
  EXPECT_EQ(m.f0[0], 900);
  EXPECT_EQ(a.count(1), 6);
  EXPECT_EQ(m.f0[1], (5 * 100 + 900 + 3) / 6);
  // Invalid: its outputs are its inputs, and it starts over after.
  f.flags = {1, 0};
  f.f0 = {-5, 900};
  f.depth = {0, 230400 - 15 * 256};
  add(a, f, m, 0, 2);
  EXPECT_EQ(a.count(0), 0);
  EXPECT_EQ(m.f0[0], -5);
  EXPECT_EQ(m.depth[0], 0);
  f.flags = {0, 0};
  f.depth = {230400, 230400 - 15 * 256};
  f.f0 = {42, 900};
  add(a, f, m, 0, 2);
  EXPECT_EQ(a.count(0), 1);
  EXPECT_EQ(m.f0[0], 42);
  a.reset();
  add(a, f, m, 0, 2);
  EXPECT_EQ(a.count(0), 1);
  EXPECT_EQ(a.count(1), 1);
  EXPECT_EQ(m.f0[1], 900);
}

TEST(FrameAccumulator, PastItsFramesTheMeanForgetsAndFollowsADrift) {
  FrameAccumulator a(1, 4, kJump);
  Frame f(1);
  Means m(1);
  f.depth[0] = 230400;
  for (int k = 0; k < 4; ++k) {
    f.f0[0] = 0;
    add(a, f, m, 0, 1);
  }
  for (int k = 0; k < 40; ++k) {  // the features step to 4000: the mean follows within a few frames' memory
    f.f0[0] = 4000;
    add(a, f, m, 0, 1);
    EXPECT_EQ(a.count(0), 4);
  }
  EXPECT_NEAR(m.f0[0], 4000, 4);
}

TEST(FrameAccumulator, TheSameValuesWhateverTheRanges) {
  const std::size_t n = 1000;
  FrameAccumulator whole(n, 8, kJump), split(n, 8, kJump);
  Frame f(n);
  Means a(n), b(n);
  std::mt19937 rng(9);
  std::uniform_int_distribution<std::int32_t> u(-2000000, 2000000), dz(-6000, 6000);
  for (int k = 0; k < 12; ++k) {
    for (std::size_t i = 0; i < n; ++i) {
      f.depth[i] = 230400 + dz(rng);
      f.f0[i] = u(rng);
      f.f1[i] = u(rng);
      f.flags[i] = (i * 7 + static_cast<std::size_t>(k)) % 97 == 0;
    }
    add(whole, f, a, 0, n);
    add(split, f, b, 0, 333);
    add(split, f, b, 333, 334);
    add(split, f, b, 334, n);
    ASSERT_EQ(a.depth, b.depth);
    ASSERT_EQ(a.f0, b.f0);
    ASSERT_EQ(a.f1, b.f1);
  }
}

TEST(FrameAccumulator, BadArgumentsAreRefused) {
  EXPECT_THROW(FrameAccumulator(4, 0, kJump), std::invalid_argument);
  EXPECT_THROW(FrameAccumulator(4, 257, kJump), std::invalid_argument);
  EXPECT_THROW(FrameAccumulator(4, 8, -1), std::invalid_argument);
  EXPECT_NO_THROW(FrameAccumulator(0, 256, 0));
}

}  // namespace
