// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// BinSpec: the binning that travels with every table. Its contract is the
// half-open interval [start + j*width, start + (j+1)*width) per bin, so the
// edges reported by lower_edge_mm()/end_mm() and index_of() must agree.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "tofmat/core/bin_spec.hpp"

namespace {

using tofmat::BinSpec;

const double kInf = std::numeric_limits<double>::infinity();
const double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(BinSpec, LinspaceOfTheRealDatabase) {
  const auto s = BinSpec::linspace(600.0, 1200.0, 200);
  EXPECT_EQ(s.start_mm, 600.0);
  EXPECT_DOUBLE_EQ(s.width_mm, 600.0 / 199.0);  // np.linspace left edges: (stop - start) / (count - 1)
  EXPECT_EQ(s.count, 200u);
  EXPECT_DOUBLE_EQ(s.lower_edge_mm(199), 1200.0);  // the last left edge is `stop`
  EXPECT_DOUBLE_EQ(s.centre_mm(0), 600.0 + 300.0 / 199.0);
  EXPECT_DOUBLE_EQ(s.end_mm(), 600.0 + 200 * 600.0 / 199.0);
  EXPECT_THROW(BinSpec::linspace(600.0, 1200.0, 1), std::invalid_argument);
  EXPECT_THROW(BinSpec::linspace(600.0, 600.0, 10), std::invalid_argument);   // width 0
  EXPECT_THROW(BinSpec::linspace(1200.0, 600.0, 10), std::invalid_argument);  // negative width
}

TEST(BinSpec, IndexOfSimpleEdges) {
  const BinSpec s{600.0, 3.0, 200};  // the live demo's 3.000 mm bins: exact in binary
  EXPECT_EQ(s.index_of(600.0), 0);
  EXPECT_EQ(s.index_of(std::nextafter(600.0, 0.0)), -1);
  EXPECT_EQ(s.index_of(602.999), 0);
  EXPECT_EQ(s.index_of(603.0), 1);
  EXPECT_EQ(s.index_of(std::nextafter(1200.0, 0.0)), 199);
  EXPECT_EQ(s.index_of(1200.0), -1);  // end is exclusive
  EXPECT_EQ(s.index_of(1e300), -1);
  EXPECT_EQ(s.index_of(-1e300), -1);
  EXPECT_EQ(s.index_of(kNaN), -1);
  EXPECT_EQ(s.index_of(kInf), -1);
  EXPECT_EQ(s.index_of(-kInf), -1);
}

TEST(BinSpec, IndexOfLinspaceStartAndEnd) {
  const auto s = BinSpec::linspace(600.0, 1200.0, 200);
  EXPECT_EQ(s.index_of(600.0), 0);
  EXPECT_EQ(s.index_of(std::nextafter(600.0, 0.0)), -1);
  EXPECT_EQ(s.index_of(1200.0), 199);  // the last left edge
  EXPECT_EQ(s.index_of(s.end_mm()), -1) << "end_mm() = " << s.end_mm() << " is outside every bin";
  EXPECT_EQ(s.index_of(std::nextafter(s.end_mm(), 0.0)), 199);
}

// Every left edge, as the class itself reports it, belongs to its own bin.
TEST(BinSpec, LowerEdgesMapToTheirOwnBin) {
  for (const BinSpec& s : {BinSpec::linspace(600.0, 1200.0, 200), BinSpec{600.0, 3.0, 200}, BinSpec{-5.0, 0.1, 100}}) {
    int wrong = 0;
    std::string first;
    for (std::uint32_t j = 0; j < s.count; ++j) {
      const auto got = s.index_of(s.lower_edge_mm(j));
      if (got != static_cast<std::int32_t>(j)) {
        if (wrong++ == 0) first = "bin " + std::to_string(j) + " edge maps to " + std::to_string(got);
      }
    }
    EXPECT_EQ(wrong, 0) << "width " << s.width_mm << ": " << wrong << " edges in the wrong bin, first: " << first;
  }
}

// The same agreement over many random binnings (fixed seed): every edge
// starts its bin, the double just below it ends the previous one, and end_mm()
// itself is outside.
TEST(BinSpec, EdgesAgreeOnRandomSpecs) {
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> start(-1e4, 1e4), log_width(-3.0, 2.0);
  std::uniform_int_distribution<std::uint32_t> count(1, tofmat::kMaxBins);
  int wrong = 0;
  std::string first;
  for (int trial = 0; trial < 2000; ++trial) {
    const BinSpec s{start(rng), std::pow(10.0, log_width(rng)), count(rng)};
    std::uniform_int_distribution<std::uint32_t> bin(0, s.count - 1);
    for (int k = 0; k < 20; ++k) {
      const std::uint32_t j = bin(rng);
      const double lo = s.lower_edge_mm(j), below_next = std::nextafter(s.lower_edge_mm(j + 1), -kInf);
      const bool ok = s.index_of(lo) == static_cast<std::int32_t>(j) &&
                      s.index_of(below_next) == static_cast<std::int32_t>(j) &&
                      s.index_of(std::nextafter(s.lower_edge_mm(0), -kInf)) == -1 && s.index_of(s.end_mm()) == -1;
      if (!ok && wrong++ == 0) {
        first = "start " + std::to_string(s.start_mm) + " width " + std::to_string(s.width_mm) + " count " +
                std::to_string(s.count) + " bin " + std::to_string(j);
      }
    }
  }
  EXPECT_EQ(wrong, 0) << "first disagreement: " << first;
}

TEST(BinSpec, Validate) {
  EXPECT_NO_THROW((BinSpec{0.0, 1.0, 1}.validate()));
  EXPECT_NO_THROW((BinSpec{-600.0, 1e-6, tofmat::kMaxBins}.validate()));
  EXPECT_THROW((BinSpec{0.0, 0.0, 10}.validate()), std::invalid_argument);
  EXPECT_THROW((BinSpec{0.0, -1.0, 10}.validate()), std::invalid_argument);
  EXPECT_THROW((BinSpec{0.0, 1.0, 0}.validate()), std::invalid_argument);
  EXPECT_THROW((BinSpec{0.0, 1.0, tofmat::kMaxBins + 1}.validate()), std::invalid_argument);
  EXPECT_THROW((BinSpec{kNaN, 1.0, 10}.validate()), std::invalid_argument);
  EXPECT_THROW((BinSpec{kInf, 1.0, 10}.validate()), std::invalid_argument);
  EXPECT_THROW((BinSpec{0.0, kNaN, 10}.validate()), std::invalid_argument);
  EXPECT_THROW((BinSpec{0.0, kInf, 10}.validate()), std::invalid_argument);
  EXPECT_THROW((BinSpec{1e308, 1e308, 10}.validate()), std::invalid_argument);  // end overflows
}

}  // namespace
