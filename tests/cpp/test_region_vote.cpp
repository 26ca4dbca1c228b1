// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Region voting on a label map (region_vote.hpp): hand-built scenes, and
// random frames against a plain flood fill with the same rules.
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <queue>
#include <random>
#include <stdexcept>
#include <vector>

#include "tofmat/core/region_vote.hpp"

namespace {

using tofmat::RegionVote;

constexpr std::uint8_t kNone = 255;
constexpr std::int32_t kStep = 10 * 256;  // 10 mm in Q8

struct Frame {
  int w, h;
  std::vector<std::int32_t> depth;
  std::vector<std::uint8_t> flags, labels;
  Frame(int width, int height)
      : w(width),
        h(height),
        depth(static_cast<std::size_t>(width * height), 0),
        flags(static_cast<std::size_t>(width * height), 1),
        labels(static_cast<std::size_t>(width * height), kNone) {}
  std::size_t at(int x, int y) const { return static_cast<std::size_t>(y * w + x); }
  // A valid rectangle at a depth (mm) rising by `slope` mm a column, labelled `label`.
  void fill(int x0, int y0, int x1, int y1, double mm, std::uint8_t label, double slope = 0.0) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) {
        depth[at(x, y)] = static_cast<std::int32_t>((mm + slope * (x - x0)) * 256.0);
        flags[at(x, y)] = 0;
        labels[at(x, y)] = label;
      }
  }
};

// The definition, by flood fill: 4-neighbour steps of at most `step` between
// valid pixels; a region of >= min_pixels whose most frequent label (ties:
// the lower) holds at least half of its labelled pixels gives it to all.
std::vector<std::uint8_t> reference(const Frame& f, std::int32_t step, std::size_t min_pixels, int classes) {
  std::vector<std::uint8_t> out = f.labels;
  std::vector<bool> seen(f.labels.size(), false);
  for (std::size_t s = 0; s < f.labels.size(); ++s) {
    if (f.flags[s] != 0 || seen[s]) continue;
    std::vector<std::size_t> region;
    std::queue<std::size_t> q;
    q.push(s);
    seen[s] = true;
    while (!q.empty()) {
      const std::size_t i = q.front();
      q.pop();
      region.push_back(i);
      const int x = static_cast<int>(i) % f.w, y = static_cast<int>(i) / f.w;
      const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
      for (int d = 0; d < 4; ++d) {
        if (nx[d] < 0 || ny[d] < 0 || nx[d] >= f.w || ny[d] >= f.h) continue;
        const std::size_t j = f.at(nx[d], ny[d]);
        if (seen[j] || f.flags[j] != 0) continue;
        if (std::llabs(static_cast<long long>(f.depth[i]) - f.depth[j]) > step) continue;
        seen[j] = true;
        q.push(j);
      }
    }
    if (region.size() < min_pixels) continue;
    std::vector<std::size_t> counts(static_cast<std::size_t>(classes), 0);
    std::size_t total = 0;
    for (std::size_t i : region)
      if (f.labels[i] < classes) ++counts[f.labels[i]], ++total;
    std::size_t best = 0;
    for (std::size_t c = 1; c < counts.size(); ++c)
      if (counts[c] > counts[best]) best = c;
    if (total == 0 || 2 * counts[best] < total) continue;
    for (std::size_t i : region) out[i] = static_cast<std::uint8_t>(best);
  }
  return out;
}

std::vector<std::uint8_t> voted(Frame f, std::int32_t step, std::size_t min_pixels, int classes) {
  RegionVote v(f.w, f.h, step, min_pixels, classes);
  v.apply(f.depth.data(), f.flags.data(), f.labels.data());
  return f.labels;
}

TEST(RegionVote, EachSurfaceTakesItsMajorityLabel) {
  Frame f(40, 20);
  f.fill(0, 0, 15, 20, 700.0, 0, 0.5);  // a tilted plane, mostly label 0
  for (int y = 0; y < 20; y += 3) f.labels[f.at(4, y)] = 1;
  f.labels[f.at(7, 7)] = kNone;     // a pixel without a label (its depth outside the table, say)
  f.fill(20, 0, 40, 20, 900.0, 2);  // beyond a gap of invalid columns: label 2
  for (int x = 20; x < 28; ++x) f.labels[f.at(x, 5)] = 0;
  f.flags[f.at(30, 10)] = 1;  // an invalid pixel keeps what it had
  f.labels[f.at(30, 10)] = 1;
  RegionVote v(f.w, f.h, kStep, 50, 3);
  v.apply(f.depth.data(), f.flags.data(), f.labels.data());
  EXPECT_EQ(v.regions_voted(), 2u);
  for (int y = 0; y < 20; ++y) {
    for (int x = 0; x < 15; ++x) EXPECT_EQ(f.labels[f.at(x, y)], 0) << x << "," << y;
    for (int x = 15; x < 20; ++x) EXPECT_EQ(f.labels[f.at(x, y)], kNone) << x << "," << y;
    for (int x = 20; x < 40; ++x) {
      if (!(x == 30 && y == 10)) {
        EXPECT_EQ(f.labels[f.at(x, y)], 2) << x << "," << y;
      }
    }
  }
  EXPECT_EQ(f.labels[f.at(30, 10)], 1);
}

TEST(RegionVote, ADepthStepSplitsSurfacesSmallOnesAndUnclearOnesKeepTheirLabels) {
  Frame f(30, 10);
  f.fill(0, 0, 15, 10, 800.0, 0);
  f.fill(15, 0, 30, 10, 811.0, 1);  // 11 mm behind: another surface
  f.labels[f.at(16, 2)] = 0;
  EXPECT_EQ(voted(f, kStep, 10, 2)[f.at(16, 2)], 1);     // split: the right surface votes 1
  EXPECT_EQ(voted(f, 11 * 256, 10, 2)[f.at(16, 2)], 0);  // one surface of 150 + 1 zeros against 149 ones
  EXPECT_EQ(voted(f, kStep, 200, 2)[f.at(16, 2)], 0);    // too small to vote
  // No label with half the labelled pixels: 40 % / 30 % / 30 %.
  Frame g(10, 10);
  g.fill(0, 0, 10, 10, 800.0, 0);
  for (int i = 40; i < 70; ++i) g.labels[static_cast<std::size_t>(i)] = 1;
  for (int i = 70; i < 100; ++i) g.labels[static_cast<std::size_t>(i)] = 2;
  EXPECT_EQ(voted(g, kStep, 10, 3), g.labels);
  // Half exactly: a tie goes to the lower label.
  for (int i = 50; i < 100; ++i) g.labels[static_cast<std::size_t>(i)] = 2;
  for (int i = 0; i < 50; ++i) g.labels[static_cast<std::size_t>(i)] = 1;
  EXPECT_EQ(voted(g, kStep, 10, 3), std::vector<std::uint8_t>(100, 1));
}

TEST(RegionVote, ExtremeDepthsDoNotOverflow) {
  Frame f(4, 1);
  f.fill(0, 0, 4, 1, 0.0, 0);
  f.depth = {std::numeric_limits<std::int32_t>::max(), std::numeric_limits<std::int32_t>::min(), 0, 0};
  f.labels = {1, 1, 0, 1};
  EXPECT_EQ(voted(f, kStep, 1, 2), reference(f, kStep, 1, 2));
}

TEST(RegionVote, MatchesAFloodFillOnRandomFrames) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    SCOPED_TRACE(trial);
    const int w = 1 + static_cast<int>(rng() % 60), h = 1 + static_cast<int>(rng() % 40);
    const int classes = 1 + static_cast<int>(rng() % 6);
    Frame f(w, h);
    std::int32_t d = 200'000;
    for (std::size_t i = 0; i < f.depth.size(); ++i) {
      // Mostly small steps, now and then a jump, some invalid pixels, labels beyond `classes` too.
      d += static_cast<std::int32_t>(rng() % 8 == 0 ? rng() % 20'000 : rng() % 2'000) -
           (rng() % 8 == 0 ? 10'000 : 1'000);
      f.depth[i] = d;
      f.flags[i] = rng() % 10 == 0 ? 1 : 0;
      f.labels[i] = static_cast<std::uint8_t>(rng() % 12 == 0 ? kNone : rng() % static_cast<unsigned>(classes + 1));
    }
    const std::size_t min_pixels = 1 + rng() % 30;
    ASSERT_EQ(voted(f, kStep, min_pixels, classes), reference(f, kStep, min_pixels, classes));
  }
}

TEST(RegionVote, BadSettingsAreRefused) {
  EXPECT_THROW(RegionVote(0, 10, kStep, 10, 3), std::invalid_argument);
  EXPECT_THROW(RegionVote(10, 10, -1, 10, 3), std::invalid_argument);
  EXPECT_THROW(RegionVote(10, 10, kStep, 0, 3), std::invalid_argument);
  EXPECT_THROW(RegionVote(10, 10, kStep, 10, 0), std::invalid_argument);
  EXPECT_THROW(RegionVote(10, 10, kStep, 10, 256), std::invalid_argument);
}

}  // namespace
