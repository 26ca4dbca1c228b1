// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The segmentation's integer smoothing (frame_smoothing.hpp) against
// brute-force definitions written here: every window summed or counted from
// scratch, pixel by pixel. Bands must give what the whole frame gives.
#include "tofmat/core/frame_smoothing.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

#include "tofmat/core/fixed_decode.hpp"

namespace {

using tofmat::BoxMeanFilter;
using tofmat::kFixedInvalid;
using tofmat::MajorityFilter;

struct Features {
  int w, h;
  std::vector<std::int32_t> f0, f1;
  std::vector<std::uint8_t> flags;
};

// Features within the decode's range (|f| < 9375 mm), a fraction invalid.
Features random_features(int w, int h, double invalid, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<std::int32_t> v(-9375 * 65536, 9375 * 65536);
  std::bernoulli_distribution bad(invalid);
  Features f{w, h, {}, {}, {}};
  const auto n = static_cast<std::size_t>(w * h);
  for (std::size_t i = 0; i < n; ++i) {
    const bool b = bad(rng);
    f.flags.push_back(b ? 1 : 0);
    f.f0.push_back(b ? kFixedInvalid : v(rng));
    f.f1.push_back(b ? kFixedInvalid : v(rng));
  }
  return f;
}

// The definition, in doubles where it can be: Q8 rounding of each value, then
// the mean rounded half up.
std::int32_t brute_mean(const Features& f, const std::vector<std::int32_t>& plane, int x, int y, int side) {
  const int r = side / 2;
  std::int64_t s = 0, n = 0;
  for (int yy = std::max(0, y - r); yy <= std::min(f.h - 1, y + r); ++yy)
    for (int xx = std::max(0, x - r); xx <= std::min(f.w - 1, x + r); ++xx) {
      const auto i = static_cast<std::size_t>(yy * f.w + xx);
      if (f.flags[i] != 0) continue;
      s += static_cast<std::int64_t>(std::floor((plane[i] + 128.0) / 256.0));
      ++n;
    }
  const double mean =
      std::floor((256.0 * static_cast<double>(s) + std::floor(static_cast<double>(n) / 2.0)) / static_cast<double>(n));
  return static_cast<std::int32_t>(
      std::clamp(mean, static_cast<double>(INT32_MIN + 1), static_cast<double>(INT32_MAX)));
}

void expect_box_means(const Features& f, int side, const std::vector<std::int32_t>& o0,
                      const std::vector<std::int32_t>& o1) {
  for (int y = 0; y < f.h; ++y)
    for (int x = 0; x < f.w; ++x) {
      const auto i = static_cast<std::size_t>(y * f.w + x);
      if (f.flags[i] != 0) {
        ASSERT_EQ(o0[i], kFixedInvalid) << x << "," << y;
        ASSERT_EQ(o1[i], kFixedInvalid) << x << "," << y;
      } else {
        ASSERT_EQ(o0[i], brute_mean(f, f.f0, x, y, side)) << x << "," << y << " side " << side;
        ASSERT_EQ(o1[i], brute_mean(f, f.f1, x, y, side)) << x << "," << y << " side " << side;
      }
    }
}

TEST(BoxMeanFilter, EveryPixelIsTheMeanOfItsWindowsValidPixels) {
  for (int side : {1, 3, 9, 15}) {
    const Features f = random_features(37, 23, 0.2, 10u + static_cast<std::uint32_t>(side));
    std::vector<std::int32_t> o0(f.f0.size(), 7), o1(f.f0.size(), 7);
    BoxMeanFilter box(f.w, f.h, side);
    box.apply(f.f0.data(), f.f1.data(), f.flags.data(), 0, f.h, o0.data(), o1.data());
    expect_box_means(f, side, o0, o1);
  }
}

TEST(BoxMeanFilter, ExtremeFeaturesAndFramesNarrowerThanTheWindow) {
  // Every valid value at the decode's extremes, frames of 1 and 2 pixels across.
  for (auto [w, h] : {std::pair{1, 1}, std::pair{2, 40}, std::pair{40, 2}, std::pair{16, 16}}) {
    Features f = random_features(w, h, 0.1, 3u);
    for (std::size_t i = 0; i < f.f0.size(); ++i)
      if (f.flags[i] == 0) f.f0[i] = (i % 2) ? 9375 * 65536 : -9375 * 65536, f.f1[i] = -9375 * 65536;
    std::vector<std::int32_t> o0(f.f0.size()), o1(f.f0.size());
    BoxMeanFilter box(w, h, 15);
    box.apply(f.f0.data(), f.f1.data(), f.flags.data(), 0, h, o0.data(), o1.data());
    expect_box_means(f, 15, o0, o1);
  }
}

TEST(BoxMeanFilter, AFullFrameAtTheExtremesWithTheWidestWindow) {
  // A 512-pixel row of 15-row columns at 9375 mm sums beyond int32: only a
  // window's sum has to fit. Checked on every 7th pixel (the brute force is slow).
  for (const std::int32_t v : {9375 * 65536, -9375 * 65536}) {
    Features f = random_features(512, 424, 0.02, 8u);
    for (std::size_t i = 0; i < f.f0.size(); ++i)
      if (f.flags[i] == 0) f.f0[i] = v, f.f1[i] = (i % 3) ? v : -v;
    std::vector<std::int32_t> o0(f.f0.size()), o1(f.f0.size());
    BoxMeanFilter box(f.w, f.h, 15);
    box.apply(f.f0.data(), f.f1.data(), f.flags.data(), 0, f.h, o0.data(), o1.data());
    for (std::size_t i = 0; i < f.f0.size(); i += 7) {
      const int x = static_cast<int>(i % 512), y = static_cast<int>(i / 512);
      if (f.flags[i] != 0) continue;
      ASSERT_EQ(o0[i], brute_mean(f, f.f0, x, y, 15)) << x << "," << y;
      ASSERT_EQ(o1[i], brute_mean(f, f.f1, x, y, 15)) << x << "," << y;
    }
  }
}

TEST(BoxMeanFilter, OutOfRangeInputStaysDefined) {
  // Values beyond the decode's range never overflow: the Q8 values fit 24
  // bits, and the mean saturates short of kFixedInvalid.
  Features f{5, 5, std::vector<std::int32_t>(25, INT32_MAX), std::vector<std::int32_t>(25, INT32_MIN + 1),
             std::vector<std::uint8_t>(25, 0)};
  std::vector<std::int32_t> o0(25), o1(25);
  BoxMeanFilter box(5, 5, 15);
  box.apply(f.f0.data(), f.f1.data(), f.flags.data(), 0, 5, o0.data(), o1.data());
  for (std::size_t i = 0; i < 25; ++i) {
    EXPECT_EQ(o0[i], INT32_MAX) << i;      // 2^23 in Q8 would be 2^31 in Q16
    EXPECT_EQ(o1[i], INT32_MIN + 1) << i;  // -2^31 would be kFixedInvalid
  }
}

TEST(BoxMeanFilter, BandsGiveWhatTheWholeFrameGives) {
  const Features f = random_features(64, 50, 0.15, 99u);
  std::vector<std::int32_t> w0(f.f0.size()), w1(f.f0.size()), b0(f.f0.size(), 1), b1(f.f0.size(), 1);
  BoxMeanFilter whole(f.w, f.h, 9), band(f.w, f.h, 9);
  whole.apply(f.f0.data(), f.f1.data(), f.flags.data(), 0, f.h, w0.data(), w1.data());
  for (auto [y0, y1] : {std::pair{0, 3}, std::pair{3, 4}, std::pair{4, 30}, std::pair{30, 50}})
    band.apply(f.f0.data(), f.f1.data(), f.flags.data(), y0, y1, b0.data(), b1.data());
  EXPECT_EQ(b0, w0);
  EXPECT_EQ(b1, w1);
}

TEST(BoxMeanFilter, TheKernelsAgreeBitForBit) {
  // Widths that are not a multiple of four (the vector kernel's tail), random
  // values over the whole int32 range as well as the decode's, every side.
  for (auto [w, h] : {std::pair{512, 60}, std::pair{37, 23}, std::pair{3, 17}}) {
    for (const bool wild : {false, true}) {
      Features f = random_features(w, h, 0.2, static_cast<std::uint32_t>(w + h + wild));
      if (wild) {
        std::mt19937 rng(7);
        for (std::size_t i = 0; i < f.f0.size(); ++i)
          f.f0[i] = static_cast<std::int32_t>(rng()), f.f1[i] = -f.f0[i] / 3;
      }
      for (int side : {1, 5, 9, 15}) {
        std::vector<std::int32_t> a0(f.f0.size()), a1(f.f0.size()), b0(f.f0.size()), b1(f.f0.size());
        BoxMeanFilter s(w, h, side), v(w, h, side);
        s.apply(f.f0.data(), f.f1.data(), f.flags.data(), 0, h, a0.data(), a1.data(), tofmat::FixedKernel::kScalar);
        v.apply(f.f0.data(), f.f1.data(), f.flags.data(), 0, h, b0.data(), b1.data(), tofmat::FixedKernel::kBest);
        ASSERT_EQ(a0, b0) << w << "x" << h << " side " << side << (wild ? " wild" : "");
        ASSERT_EQ(a1, b1) << w << "x" << h << " side " << side << (wild ? " wild" : "");
        if (wild && w == 37 && side == 5) expect_box_means(f, side, a0, a1);  // (the definition holds there too)
      }
    }
  }
}

TEST(BoxMeanFilter, RefusesBadSidesAndBands) {
  EXPECT_THROW(BoxMeanFilter(10, 10, 0), std::invalid_argument);
  EXPECT_THROW(BoxMeanFilter(10, 10, 4), std::invalid_argument);
  EXPECT_THROW(BoxMeanFilter(10, 10, 17), std::invalid_argument);
  EXPECT_THROW(BoxMeanFilter(0, 10, 3), std::invalid_argument);
  BoxMeanFilter box(4, 4, 3);
  std::vector<std::int32_t> f(16, 0), o(16);
  std::vector<std::uint8_t> flags(16, 0);
  EXPECT_THROW(box.apply(f.data(), f.data(), flags.data(), 2, 5, o.data(), o.data()), std::invalid_argument);
  EXPECT_THROW(box.apply(f.data(), f.data(), flags.data(), -1, 2, o.data(), o.data()), std::invalid_argument);
  EXPECT_THROW(box.apply(f.data(), f.data(), flags.data(), 3, 2, o.data(), o.data()), std::invalid_argument);
}

// The majority filter's definition, counted window by window.
std::uint8_t brute_majority(const std::vector<std::uint8_t>& l, int w, int h, int x, int y, int side, int classes) {
  const std::uint8_t own = l[static_cast<std::size_t>(y * w + x)];
  std::vector<int> count(static_cast<std::size_t>(classes), 0);
  int window = 0, labelled = 0;
  const int r = side / 2;
  for (int yy = std::max(0, y - r); yy <= std::min(h - 1, y + r); ++yy)
    for (int xx = std::max(0, x - r); xx <= std::min(w - 1, x + r); ++xx) {
      const std::uint8_t v = l[static_cast<std::size_t>(yy * w + xx)];
      ++window;
      if (v < classes) ++count[v], ++labelled;
    }
  if (own >= classes && 2 * labelled <= window) return own;
  const int most = *std::max_element(count.begin(), count.end());
  if (own < classes && count[own] == most) return own;
  for (int c = 0; c < classes; ++c)
    if (count[static_cast<std::size_t>(c)] == most) return static_cast<std::uint8_t>(c);
  return own;
}

std::vector<std::uint8_t> random_labels(int w, int h, int classes, double unlabelled, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> c(0, classes - 1);
  std::uniform_int_distribution<int> other(classes, 255);
  std::bernoulli_distribution none(unlabelled);
  std::vector<std::uint8_t> out(static_cast<std::size_t>(w * h));
  // Blocks of one class with noise, so that majorities are not all ties.
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int block = ((x / 7) * 31 + (y / 5) * 17) % classes;
      const int v = none(rng) ? (classes < 255 ? other(rng) : 255) : (rng() % 3 == 0 ? c(rng) : block);
      out[static_cast<std::size_t>(y * w + x)] = static_cast<std::uint8_t>(v);
    }
  return out;
}

TEST(MajorityFilter, EveryLabelIsItsWindowsMajority) {
  for (int classes : {1, 2, 5, 15, 16, 17, 40, 254, 255})
    for (int side : {1, 3, 9, 15})
      // (frames narrower and lower than the window too: its edges overlap)
      for (auto [w, h] : {std::pair{41, 29}, std::pair{3, 20}, std::pair{10, 4}, std::pair{16, 16}}) {
        const auto l = random_labels(w, h, classes, 0.1, static_cast<std::uint32_t>(classes * 100 + side + w));
        std::vector<std::uint8_t> out(l.size(), 77);
        MajorityFilter mf(w, h, side, classes);
        mf.apply(l.data(), 0, h, out.data());
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x)
            ASSERT_EQ(out[static_cast<std::size_t>(y * w + x)], brute_majority(l, w, h, x, y, side, classes))
                << "classes " << classes << " side " << side << " " << w << "x" << h << " at " << x << "," << y;
      }
}

TEST(MajorityFilter, CleansIsolatedPixelsAndKeepsEdges) {
  // Two halves, 0 and 1, with a lone 1 inside the 0s, a lone unlabelled pixel
  // inside the 0s, and an unlabelled border 3 rows deep along the top.
  const int w = 20, h = 10;
  std::vector<std::uint8_t> l(static_cast<std::size_t>(w * h));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) l[static_cast<std::size_t>(y * w + x)] = x < 10 ? 0 : 1;
  l[static_cast<std::size_t>(5 * w + 4)] = 1;
  l[static_cast<std::size_t>(3 * w + 3)] = 255;
  for (std::size_t i = 0; i < static_cast<std::size_t>(3 * w); ++i) l[i] = 255;
  std::vector<std::uint8_t> out(l.size());
  MajorityFilter mf(w, h, 5, 2);
  mf.apply(l.data(), 0, h, out.data());
  EXPECT_EQ(out[static_cast<std::size_t>(5 * w + 4)], 0);  // the lone 1: outvoted
  EXPECT_EQ(out[static_cast<std::size_t>(3 * w + 3)], 0);  // the hole: filled
  for (std::size_t i = 0; i < static_cast<std::size_t>(3 * w); ++i)
    EXPECT_EQ(out[i], 255) << i;  // the border: at least 3 of its windows' 5 rows are empty
  for (int y = 3; y < h; ++y) {
    EXPECT_EQ(out[static_cast<std::size_t>(y * w + 9)], 0);  // the edge stays where it is
    EXPECT_EQ(out[static_cast<std::size_t>(y * w + 10)], 1);
  }
}

TEST(MajorityFilter, BandsGiveWhatTheWholeFrameGives) {
  const int w = 70, h = 45;
  const auto l = random_labels(w, h, 6, 0.2, 5u);
  std::vector<std::uint8_t> whole(l.size()), bands(l.size(), 9);
  MajorityFilter a(w, h, 9, 6), b(w, h, 9, 6);
  a.apply(l.data(), 0, h, whole.data());
  for (auto [y0, y1] : {std::pair{0, 1}, std::pair{1, 20}, std::pair{20, 20}, std::pair{20, 45}})
    b.apply(l.data(), y0, y1, bands.data());
  EXPECT_EQ(bands, whole);
}

TEST(MajorityFilter, RefusesBadArguments) {
  EXPECT_THROW(MajorityFilter(10, 10, 9, 0), std::invalid_argument);
  EXPECT_THROW(MajorityFilter(10, 10, 9, 256), std::invalid_argument);
  EXPECT_THROW(MajorityFilter(10, 10, 2, 3), std::invalid_argument);
  MajorityFilter mf(4, 4, 3, 3);
  std::vector<std::uint8_t> l(16, 0), o(16);
  EXPECT_THROW(mf.apply(l.data(), 0, 5, o.data()), std::invalid_argument);
}

}  // namespace
