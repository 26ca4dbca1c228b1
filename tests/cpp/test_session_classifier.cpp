// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session-robust matcher (session_classifier.hpp) on cases worked by hand:
// the Gaussian marginal likelihood of an offset in closed form, an outlier
// down-weighted, a gap charged, the roughness of a known noise. (Its equality
// with the NumPy reference on real queries: tests/python/test_session_classifier.py.)
#include "tofmat/core/session_classifier.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <stdexcept>
#include <vector>

namespace {

using namespace tofmat;
constexpr double kLog2Pi = 1.8378770664093453;

std::shared_ptr<const ExemplarTable> table_of(std::vector<float> values, std::size_t materials, std::uint32_t rows,
                                              std::uint32_t bins) {
  std::vector<std::string> names;
  for (std::size_t m = 0; m < materials; ++m) names.push_back("m" + std::to_string(m));
  std::vector<RowSpec> spec(rows, RowSpec{0, 0});
  return std::make_shared<const ExemplarTable>(names, spec, BinSpec{600.0, 3.0, bins}, std::move(values));
}

SessionPrior offset_only(double s, double floor_mm, double huber_k) {
  SessionPrior p;
  p.offset_sd_mm = {s};
  p.drift1_sd_mm = p.drift2_sd_mm = 0.0;
  p.noise_scale = 0.0;
  p.floor_mm = floor_mm;
  p.huber_k = huber_k;
  return p;
}

TEST(SessionClassifier, AnOffsetsMarginalLikelihoodInClosedForm) {
  // One row of 8 bins, one material at 0; the query 1.5 + small wiggles.
  const std::uint32_t bins = 8;
  auto t = table_of(std::vector<float>(bins, 0.0f), 1, 1, bins);
  std::vector<float> q(bins);
  for (std::uint32_t j = 0; j < bins; ++j) q[j] = static_cast<float>(1.5 + 0.1 * ((j % 3) - 1.0));
  const double s = 2.0, v = 0.25;  // offset prior sd, noise variance (floor 0.5)
  SessionClassifier c(t, offset_only(s, 0.5, std::numeric_limits<double>::infinity()), {1.0});
  const double got = c.classify(q.data(), q.size()).best().distance;
  // -log of N(e; 0, v I + s^2 1 1^T), by the matrix determinant lemma and Sherman-Morrison.
  double se = 0.0, see = 0.0;
  for (float e : q) {
    se += e;
    see += static_cast<double>(e) * e;
  }
  const double n = bins, prec = n / v + 1.0 / (s * s);
  const double want =
      0.5 * (see / v - (se / v) * (se / v) / prec) + 0.5 * n * (kLog2Pi + std::log(v)) + 0.5 * std::log(s * s * prec);
  EXPECT_NEAR(got, want, 1e-12 * std::fabs(want));
}

TEST(SessionClassifier, OffsetsAreForgivenWhereEq12CountsThem) {
  // Two materials of different shape; the query is material 0 moved by 3 mm.
  const std::uint32_t bins = 30;
  std::vector<float> v(2 * bins);
  for (std::uint32_t j = 0; j < bins; ++j) {
    v[j] = static_cast<float>(0.6 * std::sin(0.2 * j));
    v[bins + j] = static_cast<float>(2.0 + 0.6 * std::sin(0.2 * j + 1.0));
  }
  auto t = table_of(v, 2, 1, bins);
  std::vector<float> q(v.begin(), v.begin() + bins);
  for (float& x : q) x += 3.0f;
  EXPECT_EQ(FloatClassifier(t).classify(q.data(), q.size()).best().index, 1u);  // Eq. (12): the nearer level
  SessionClassifier c(t, offset_only(3.0, 0.05, 3.0), {0.02, 0.02});
  EXPECT_EQ(c.classify(q.data(), q.size()).best().index, 0u);
}

TEST(SessionClassifier, AnOutlierBinIsDownWeighted) {
  const std::uint32_t bins = 10;
  std::vector<float> v(2 * bins, 0.0f);
  for (std::uint32_t j = 0; j < bins; ++j) v[bins + j] = 1.0f;
  auto t = table_of(v, 2, 1, bins);
  std::vector<float> q(bins, 0.0f);
  q[5] = 60.0f;
  const std::vector<double> noise{0.1, 0.1};
  SessionPrior robust = offset_only(0.01, 0.0, 3.0), gauss = robust;
  robust.noise_scale = gauss.noise_scale = 1.0;
  gauss.huber_k = std::numeric_limits<double>::infinity();
  EXPECT_EQ(SessionClassifier(t, robust, noise).classify(q.data(), q.size()).best().index, 0u);
  EXPECT_EQ(SessionClassifier(t, gauss, noise).classify(q.data(), q.size()).best().index, 1u);
}

TEST(SessionClassifier, AGapIsNoAdvantage) {
  // The query equals material 0 over 10 bins; material 2 equals it too but
  // has only the first 5 of them, material 1 none. The 5 elements material 2
  // lacks are charged a matching element's cost, so it does not beat the
  // complete match; material 1 shares nothing and is no candidate.
  const std::uint32_t bins = 10;
  std::vector<float> v(3 * bins, 0.3f);
  for (std::uint32_t j = 0; j < bins; ++j) v[bins + j] = std::nanf("");
  for (std::uint32_t j = 5; j < bins; ++j) v[2 * bins + j] = std::nanf("");
  auto t = table_of(v, 3, 1, bins);
  std::vector<float> q(bins, 0.3f);
  SessionClassifier c(t, SessionPrior::tuned(*t), {0.2, 0.2, 0.2});
  const Classification r = c.classify(q.data(), q.size());
  ASSERT_EQ(r.ranking.size(), 2u);
  EXPECT_EQ(r.ranking[0].index, 0u);
  EXPECT_EQ(r.ranking[0].valid, 10u);
  EXPECT_EQ(r.ranking[1].index, 2u);
  EXPECT_EQ(r.ranking[1].valid, 5u);
  EXPECT_LT(r.ranking[0].distance, r.ranking[1].distance);
  // Ties go to the lower index: two identical materials.
  auto twins = table_of(std::vector<float>(2 * bins, 0.3f), 2, 1, bins);
  const Classification tie = SessionClassifier(twins, SessionPrior::tuned(*twins)).classify(q.data(), q.size());
  EXPECT_EQ(tie.ranking[0].distance, tie.ranking[1].distance);
  EXPECT_EQ(tie.ranking[0].index, 0u);
}

TEST(SessionClassifier, RoughnessOfAKnownNoise) {
  const std::uint32_t bins = 4000;
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.3);
  std::vector<float> v(bins);
  for (std::uint32_t j = 0; j < bins; ++j) v[j] = static_cast<float>(5.0 + 0.001 * j + noise(rng));
  const std::vector<double> r = curve_roughness(*table_of(v, 1, 1, bins));
  EXPECT_NEAR(r[0], 0.3, 0.02);
  std::vector<float> few(bins, std::nanf(""));
  few[0] = few[1] = few[2] = few[3] = 1.0f;
  EXPECT_TRUE(std::isnan(curve_roughness(*table_of(few, 1, 1, bins))[0]));
}

TEST(SessionClassifier, UsesTheTablesNoiseWhereItHoldsOne) {
  // Two materials of one row: a rough one (roughness measurable) and one
  // whose stored noise differs from its roughness; a NaN entry falls back.
  const std::uint32_t bins = 400;
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.3);
  std::vector<float> v(2 * bins);
  for (auto& x : v) x = static_cast<float>(noise(rng));
  const auto plain = table_of(v, 2, 1, bins);
  const std::vector<double> rough = curve_roughness(*plain);
  const auto stored = std::make_shared<const ExemplarTable>(plain->with_noise({std::nanf(""), 1.75f}));
  SessionClassifier c(stored, SessionPrior::tuned(*stored));
  EXPECT_EQ(c.noise_mm()[0], rough[0]);
  EXPECT_EQ(c.noise_mm()[1], 1.75);
  // An explicit noise still wins over the table's.
  SessionClassifier given(stored, SessionPrior::tuned(*stored), {0.5, 0.25});
  EXPECT_EQ(given.noise_mm(), (std::vector<double>{0.5, 0.25}));
}

TEST(SessionClassifier, TheCubeRootIsTheLibrarysWithinAFewUlp) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> exponent(-300.0, 300.0), sign(-1.0, 1.0);
  double worst = 0.0;
  for (int i = 0; i < 200000; ++i) {
    const double x = std::copysign(std::pow(10.0, exponent(rng)), sign(rng));
    const double want = std::cbrt(x), got = cube_root(x);
    const double ulp = std::nextafter(std::fabs(want), std::numeric_limits<double>::infinity()) - std::fabs(want);
    worst = std::max(worst, std::fabs(got - want) / ulp);
  }
  EXPECT_LE(worst, 5.0);  // (4 ulp of the true root, std::cbrt's within 1)
  // Exact cubes, the ends of the normal range, and the exponent's residues 0, 1, 2 either side of 1.
  for (const double x :
       {1.0, 8.0, 27.0, -64.0, 0.125, std::numeric_limits<double>::min(), std::numeric_limits<double>::max(),
        -std::numeric_limits<double>::max(), 2.0, 4.0, 0.5, 0.25}) {
    const double want = std::cbrt(x);
    const double ulp = std::nextafter(std::fabs(want), std::numeric_limits<double>::infinity()) - std::fabs(want);
    EXPECT_LE(std::fabs(cube_root(x) - want), 4.0 * ulp) << x;
  }
  EXPECT_EQ(cube_root(8.0), 2.0);
  EXPECT_EQ(cube_root(-27.0), -3.0);
  // The library's own rules outside the normal numbers.
  EXPECT_EQ(cube_root(0.0), 0.0);
  EXPECT_TRUE(std::signbit(cube_root(-0.0)));
  EXPECT_EQ(cube_root(std::numeric_limits<double>::infinity()), std::numeric_limits<double>::infinity());
  EXPECT_EQ(cube_root(-std::numeric_limits<double>::infinity()), -std::numeric_limits<double>::infinity());
  EXPECT_TRUE(std::isnan(cube_root(std::nan(""))));
  volatile double tiny = std::numeric_limits<double>::denorm_min();  // (at run time: the compiler folds a constant's
  EXPECT_EQ(cube_root(tiny), std::cbrt(tiny));                       // cbrt correctly rounded, glibc's within 1 ulp)
}

TEST(SessionClassifier, AFitIsTheChiSquaresDeviate) {
  // Wilson-Hilferty: q = n gives (1 - (1 - a)) / sqrt(a), a = 2 / (9 n).
  const double a = 2.0 / 900.0;
  EXPECT_NEAR(chi_square_deviate(100.0, 100.0), a / std::sqrt(a), 1e-12);
  EXPECT_LT(chi_square_deviate(0.0, 5.0), -3.0);
  EXPECT_GT(chi_square_deviate(300.0, 100.0), 8.0);
  // Offsets only, Gaussian, one row: Q = 2 (data + penalty) in closed form.
  // Query = curve + c: with prior variance s^2 and noise v the posterior
  // offset is c n s^2 / (v + n s^2), and Q = n c^2 / (v + n s^2).
  const double s = 2.0, floor_mm = 0.5, v = floor_mm * floor_mm, c = 3.0;
  const std::uint32_t n = 8;
  auto t = table_of(std::vector<float>(n, 1.0f), 1, 1, n);
  SessionClassifier clf(t, offset_only(s, floor_mm, std::numeric_limits<double>::infinity()));
  std::vector<float> q(n, static_cast<float>(1.0 + c));
  const double want_q = n * c * c / (v + n * s * s);
  EXPECT_NEAR(clf.classify(q.data(), q.size()).best().fit, chi_square_deviate(want_q, n), 1e-9);
}

TEST(SessionClassifier, AMaterialNoisierThanTheTablesTypicalOneIsVague) {
  // Element variance (noise_scale sigma)^2 + floor^2 over the row's median, averaged over the rows.
  SessionPrior p;
  p.offset_sd_mm = {1.0, 1.0};
  p.noise_scale = 2.0;
  p.floor_mm = 0.0;
  // Rows of sigma 0.1, 0.1, 1.0 (variances 0.04, 0.04, 4: median 0.04) and 0.2, 0.1, 0.1 (0.16, 0.04, 0.04).
  const std::vector<double> noise = {0.1, 0.2, 0.1, 0.1, 1.0, 0.1};
  const auto v = candidate_vagueness(noise, 2, p);
  ASSERT_EQ(v.size(), 3u);
  EXPECT_NEAR(v[0], (1.0 + 4.0) / 2.0, 1e-12);
  EXPECT_NEAR(v[1], 1.0, 1e-12);
  EXPECT_NEAR(v[2], (100.0 + 1.0) / 2.0, 1e-12);
  // The floor is everyone's: with one of 2 mm no material is much noisier than another.
  p.floor_mm = 2.0;
  for (double x : candidate_vagueness(noise, 2, p)) EXPECT_LT(x, 1.6);
  EXPECT_THROW(candidate_vagueness(noise, 4, p), std::invalid_argument);  // 6 values are not 4 rows
  // The classifier's own, from its noise and prior.
  std::vector<float> values(3 * 2 * 8);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<float>(i % 5);
  p.floor_mm = 0.0;
  const SessionClassifier clf(table_of(values, 3, 2, 8), p, noise);
  EXPECT_EQ(clf.vagueness(), candidate_vagueness(noise, 2, p));
}

TEST(SessionClassifier, BadSettingsAndQueriesAreClearErrors) {
  auto t = table_of(std::vector<float>(2 * 4, 0.0f), 1, 2, 4);
  SessionPrior p = SessionPrior::tuned(*t);
  EXPECT_EQ(p.offset_sd_mm, (std::vector<double>{1.0, 1.0}));             // rows of unknown frequency
  EXPECT_THROW(SessionClassifier(t, p, {1.0}), std::invalid_argument);    // noise of the wrong size
  EXPECT_THROW(SessionClassifier(t, p, {}, {3}), std::invalid_argument);  // candidate outside
  p.offset_sd_mm = {1.0};
  EXPECT_THROW(SessionClassifier(t, p), std::invalid_argument);
  p.offset_sd_mm = {1.0, -1.0};
  EXPECT_THROW(SessionClassifier(t, p), std::invalid_argument);
  p.offset_sd_mm = {1.0, 1.0};
  p.noise_scale = p.floor_mm = 0.0;
  EXPECT_THROW(SessionClassifier(t, p), std::invalid_argument);
  p = SessionPrior::tuned(*t);
  p.huber_k = 0.0;
  EXPECT_THROW(SessionClassifier(t, p), std::invalid_argument);
  p = SessionPrior::tuned(*t);
  p.iterations = 0;
  EXPECT_THROW(SessionClassifier(t, p), std::invalid_argument);
  SessionClassifier c(t, SessionPrior::tuned(*t));
  std::vector<float> q(8, std::nanf(""));
  EXPECT_THROW(c.classify(q.data(), q.size()), std::invalid_argument);  // nothing valid
  EXPECT_THROW(c.classify(q.data(), 7), std::invalid_argument);         // wrong size
  q[0] = std::numeric_limits<float>::infinity();
  EXPECT_THROW(c.classify(q.data(), q.size()), std::invalid_argument);
}

}  // namespace
