// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FastNormal (firmware/sim gaussian.hpp): the ziggurat standard normal used for
// sensor noise. Moments, tails, the shape of the distribution, independence of
// successive samples, and determinism by seed.
//
// Every bound is a multiple of the statistic's standard error for a correct
// N(0, 1) generator (given next to it), so a correct generator passes with
// overwhelming probability for any seed while a biased one fails. The seeds
// are fixed, so the run is reproducible.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "tofmat/sim/gaussian.hpp"

namespace {

using tofmat::sim::FastNormal;

double phi(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }
double two_sided_tail(double x) { return std::erfc(x / std::sqrt(2.0)); }  // P(|X| > x)

std::vector<double> draw(std::uint64_t seed, std::size_t n) {
  FastNormal g(seed);
  std::vector<double> v(n);
  for (auto& x : v) x = g();
  return v;
}

TEST(FastNormal, MomentsOfAMillionSamples) {
  const std::size_t n = 1000000;
  const auto v = draw(20170721, n);
  double s1 = 0, s2 = 0, s3 = 0, s4 = 0;
  for (double x : v) {
    ASSERT_TRUE(std::isfinite(x));
    s1 += x;
  }
  const double mean = s1 / n;
  for (double x : v) {
    const double d = x - mean, d2 = d * d;
    s2 += d2;
    s3 += d2 * d;
    s4 += d2 * d2;
  }
  const double var = s2 / n, skew = s3 / n / std::pow(var, 1.5), kurt = s4 / n / (var * var);
  EXPECT_NEAR(mean, 0.0, 5e-3);  // standard error 1e-3
  EXPECT_NEAR(var, 1.0, 1e-2);   // standard error sqrt(2/n) = 1.4e-3
  EXPECT_NEAR(skew, 0.0, 0.03);  // standard error sqrt(6/n) = 2.4e-3
  EXPECT_NEAR(kurt, 3.0, 0.05);  // standard error sqrt(24/n) = 4.9e-3
  RecordProperty("mean", std::to_string(mean));
  RecordProperty("variance", std::to_string(var));
  RecordProperty("kurtosis", std::to_string(kurt));
}

TEST(FastNormal, TailFractions) {
  // 4e7 samples: P(|x| > 4) = 6.33e-5 gives ~2530 counts, so 10 % is 5
  // Poisson standard deviations (with 1e6 samples it would be 63 counts and
  // 10 % less than one standard deviation: a coin flip, not a test).
  const std::size_t n = 40000000;
  FastNormal g(7);
  const double cuts[] = {2.0, 3.0, 3.4426, 3.5, 4.0, 4.5};
  std::size_t counts[6] = {0, 0, 0, 0, 0, 0};
  double max_abs = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double a = std::fabs(g());
    max_abs = std::max(max_abs, a);
    for (int c = 0; c < 6; ++c) counts[c] += a > cuts[c] ? 1u : 0u;
  }
  const double rel_bound[] = {0.10, 0.10, 0.10, 0.10, 0.10, 0.30};  // 4.5: 272 counts, 30 % = 5 sd
  for (int c = 0; c < 6; ++c) {
    const double want = two_sided_tail(cuts[c]);
    const double got = static_cast<double>(counts[c]) / static_cast<double>(n);
    EXPECT_NEAR(got / want, 1.0, rel_bound[c]) << "P(|x| > " << cuts[c] << "): " << got << " vs " << want;
  }
  // The ziggurat's tail (beyond r = 3.4426) is sampled, not cut off: with 4e7
  // samples the largest is > 5 with probability 1 - (1 - 5.7e-7)^4e7 ~ 1.
  EXPECT_GT(max_abs, 5.0);
  EXPECT_LT(max_abs, 8.0);  // P(|x| > 8) * 4e7 = 5e-8
}

// The shape across the 128 ziggurat layers: a chi-square over 0.1-wide bins
// from -5 to 5 (4e7 samples, expected counts >= 170 per bin). For 100 bins +
// 2 tails (101 d.o.f.) the statistic has mean 101 and sd 14.2; bound 200 (~7 sd).
TEST(FastNormal, HistogramMatchesTheNormalDensity) {
  const std::size_t n = 40000000;
  const int bins = 100;
  std::vector<double> counts(static_cast<std::size_t>(bins) + 2, 0.0);
  FastNormal g(123456789);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = g();
    std::size_t b;
    if (x < -5.0) {
      b = 0;
    } else if (x >= 5.0) {
      b = static_cast<std::size_t>(bins) + 1;
    } else {
      b = 1 + std::min(static_cast<std::size_t>((x + 5.0) * 10.0), static_cast<std::size_t>(bins - 1));
    }
    counts[b] += 1.0;
  }
  double chi2 = 0.0, worst = 0.0;
  for (int b = 0; b < bins + 2; ++b) {
    double p;
    if (b == 0) {
      p = phi(-5.0);
    } else if (b == bins + 1) {
      p = 1.0 - phi(5.0);
    } else {
      p = phi(-5.0 + 0.1 * b) - phi(-5.0 + 0.1 * (b - 1));
    }
    const double e = p * static_cast<double>(n);
    const double d = counts[static_cast<std::size_t>(b)] - e;
    chi2 += d * d / e;
    worst = std::max(worst, std::fabs(d) / std::sqrt(e));
  }
  EXPECT_LT(chi2, 200.0);
  EXPECT_LT(worst, 5.5);  // no single bin beyond 5.5 sd (P ~ 4e-8 each)
  RecordProperty("chi2", std::to_string(chi2));
}

// Kolmogorov-Smirnov on 1e6 samples: sup |F_n - Phi| < 1.95 / sqrt(n) at the 0.1 % level.
TEST(FastNormal, KolmogorovSmirnov) {
  const std::size_t n = 1000000;
  auto v = draw(99, n);
  std::sort(v.begin(), v.end());
  double d = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double f = phi(v[i]);
    d = std::max({d, std::fabs(f - static_cast<double>(i) / n), std::fabs(static_cast<double>(i + 1) / n - f)});
  }
  EXPECT_LT(d, 1.95 / std::sqrt(static_cast<double>(n)));
  RecordProperty("ks_d", std::to_string(d));
}

TEST(FastNormal, SymmetryAndIndependenceOfSuccessiveSamples) {
  const std::size_t n = 1000000;
  const auto v = draw(5, n);
  std::size_t positive = 0;
  double lag1 = 0.0, lag2 = 0.0, sq_lag1 = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    positive += v[i] > 0 ? 1u : 0u;
    if (i + 1 < n) lag1 += v[i] * v[i + 1];
    if (i + 2 < n) lag2 += v[i] * v[i + 2];
    if (i + 1 < n) sq_lag1 += (v[i] * v[i] - 1.0) * (v[i + 1] * v[i + 1] - 1.0);
  }
  // Each: standard error 1/sqrt(n) = 1e-3 (sqrt(2)/sqrt(n)... for the squares: 2e-3); bounds 5 se.
  EXPECT_NEAR(static_cast<double>(positive) / n, 0.5, 2.5e-3);
  EXPECT_NEAR(lag1 / n, 0.0, 5e-3);
  EXPECT_NEAR(lag2 / n, 0.0, 5e-3);
  EXPECT_NEAR(sq_lag1 / n, 0.0, 1e-2);
}

TEST(FastNormal, DeterministicBySeed) {
  FastNormal a(42), b(42), c(43), z(0);
  int differ = 0;
  for (int i = 0; i < 10000; ++i) {
    const double x = a(), y = b(), w = c();
    ASSERT_EQ(x, y) << i;  // bit-identical
    differ += x != w ? 1 : 0;
    ASSERT_TRUE(std::isfinite(z()));  // seed 0 is a valid seed
  }
  EXPECT_GE(differ, 9990);
}

}  // namespace
