// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// DepthBinAccumulator: per-frame observations averaged into depth bins, the
// partial query a hand-held sweep builds up for the classifier.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "tofmat/core/depth_bins.hpp"

namespace {

using tofmat::BinSpec;
using tofmat::DepthBinAccumulator;

const float kNaN = std::numeric_limits<float>::quiet_NaN();
const float kInf = std::numeric_limits<float>::infinity();

// 2 rows x 4 bins of 10 mm from 100 mm: bins [100,110) [110,120) [120,130) [130,140).
DepthBinAccumulator make() { return DepthBinAccumulator(BinSpec{100.0, 10.0, 4}, 2); }

TEST(DepthBins, MeanPerBin) {
  auto acc = make();
  const float a[2] = {1.0f, 10.0f}, b[2] = {2.0f, 20.0f}, c[2] = {4.0f, -4.0f};
  EXPECT_EQ(acc.add(100.0, a), 0);
  EXPECT_EQ(acc.add(109.9, b), 0);
  EXPECT_EQ(acc.add(135.0, c), 3);
  const auto q = acc.query();
  ASSERT_EQ(q.size(), 8u);  // row-major: row 0 bins 0..3, then row 1
  EXPECT_FLOAT_EQ(q[0], 1.5f);
  EXPECT_FLOAT_EQ(q[4], 15.0f);
  EXPECT_FLOAT_EQ(q[3], 4.0f);
  EXPECT_FLOAT_EQ(q[7], -4.0f);
  for (int i : {1, 2, 5, 6}) EXPECT_TRUE(std::isnan(q[i])) << i;
  EXPECT_EQ(acc.count(0, 0), 2u);
  EXPECT_EQ(acc.count(1, 3), 1u);
  EXPECT_EQ(acc.count(0, 1), 0u);
  EXPECT_THROW(acc.count(2, 0), std::out_of_range);
  EXPECT_THROW(acc.count(0, 4), std::out_of_range);
}

TEST(DepthBins, NanRowValuesAreSkipped) {
  auto acc = make();
  const float only_row1[2] = {kNaN, 3.0f}, both[2] = {5.0f, 7.0f};
  EXPECT_EQ(acc.add(115.0, only_row1), 1);
  EXPECT_EQ(acc.add(115.0, both), 1);
  EXPECT_EQ(acc.count(0, 1), 1u);
  EXPECT_EQ(acc.count(1, 1), 2u);
  const auto q = acc.query();
  EXPECT_FLOAT_EQ(q[1], 5.0f);  // the NaN did not drag row 0's mean
  EXPECT_FLOAT_EQ(q[5], 5.0f);
  const float none[2] = {kNaN, kNaN};
  EXPECT_EQ(acc.add(125.0, none), 2);  // bin found, nothing added
  EXPECT_EQ(acc.count(0, 2), 0u);
  EXPECT_EQ(acc.bins_covered(), 1u);
}

TEST(DepthBins, MinCountAndCoverage) {
  auto acc = make();
  const float v[2] = {1.0f, 2.0f}, row0[2] = {3.0f, kNaN};
  acc.add(101.0, v);
  acc.add(102.0, v);
  acc.add(102.0, row0);  // bin 0: row 0 has 3, row 1 has 2
  acc.add(121.0, v);     // bin 2: 1 each
  EXPECT_EQ(acc.bins_covered(), 2u);
  EXPECT_EQ(acc.bins_covered(0), 2u);  // 0 means 1
  EXPECT_EQ(acc.bins_covered(2), 1u);
  EXPECT_EQ(acc.bins_covered(3), 1u);  // one row with 3 is enough
  EXPECT_EQ(acc.bins_covered(4), 0u);
  const auto q = acc.query(3);
  EXPECT_FLOAT_EQ(q[0], 5.0f / 3.0f);
  EXPECT_TRUE(std::isnan(q[4]));  // row 1 of bin 0 has only 2
  EXPECT_TRUE(std::isnan(q[2]));
  const auto q0 = acc.query(0);
  EXPECT_FLOAT_EQ(q0[2], 1.0f);
}

TEST(DepthBins, OutOfRangeAddsNothing) {
  auto acc = make();
  const float v[2] = {1.0f, 2.0f};
  for (double d : {99.999, 140.0, 1e9, -1.0, static_cast<double>(kNaN), static_cast<double>(kInf)}) {
    EXPECT_EQ(acc.add(d, v), -1) << d;
  }
  EXPECT_EQ(acc.bins_covered(), 0u);
  for (float x : acc.query()) EXPECT_TRUE(std::isnan(x));
}

TEST(DepthBins, InfiniteValueThrowsAndAddsNothing) {
  auto acc = make();
  const float bad[2] = {1.0f, kInf}, bad2[2] = {-kInf, 1.0f};
  EXPECT_THROW(acc.add(105.0, bad), std::invalid_argument);
  EXPECT_THROW(acc.add(105.0, bad2), std::invalid_argument);
  EXPECT_EQ(acc.count(0, 0), 0u) << "row 0 was added before row 1's Inf was noticed";
  EXPECT_EQ(acc.count(1, 0), 0u);
}

TEST(DepthBins, Reset) {
  auto acc = make();
  const float v[2] = {1.0f, 2.0f}, w[2] = {9.0f, 9.0f};
  acc.add(105.0, v);
  acc.reset();
  EXPECT_EQ(acc.bins_covered(), 0u);
  EXPECT_EQ(acc.count(0, 0), 0u);
  acc.add(105.0, w);
  EXPECT_FLOAT_EQ(acc.query()[0], 9.0f);  // nothing of the old sum survives
}

TEST(DepthBins, ConstructorValidates) {
  EXPECT_THROW(DepthBinAccumulator(BinSpec{0.0, 0.0, 4}, 2), std::invalid_argument);
  EXPECT_THROW(DepthBinAccumulator(BinSpec{0.0, 1.0, 0}, 2), std::invalid_argument);
  EXPECT_THROW(DepthBinAccumulator(BinSpec{0.0, 1.0, 4}, 0), std::invalid_argument);
  EXPECT_THROW(DepthBinAccumulator(BinSpec{0.0, 1.0, 4}, 17), std::invalid_argument);
  const DepthBinAccumulator ok(BinSpec{0.0, 1.0, 4}, 16);
  EXPECT_EQ(ok.n_rows(), 16u);
  EXPECT_EQ(ok.query().size(), 64u);
}

// Averaging many frames: the sum is kept in double, so a long sweep of values
// with a large common offset still gives the exact mean.
TEST(DepthBins, LongSweepMeanIsAccurate) {
  DepthBinAccumulator acc(BinSpec{600.0, 3.0, 1}, 1);
  for (int i = 0; i < 100000; ++i) {
    const float v[1] = {i % 2 == 0 ? 90.25f : 90.75f};
    acc.add(601.0, v);
  }
  EXPECT_FLOAT_EQ(acc.query()[0], 90.5f);
  EXPECT_EQ(acc.count(0, 0), 100000u);
}

}  // namespace
