// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's fixed-point path against its float reference on the
// same quantised table and queries: every score within the budget of
// docs/numerics.md, the same labels, under every kind of setting, on sweeps
// of the real curves moved by a session's offsets, with noise and outliers;
// the stiff cases (saturated queries, one element, no nuisance term, all
// outliers); the same errors.
#include "tofmat/core/fixed_session_classifier.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "test_util.hpp"
#include "tofmat/core/session_classifier.hpp"

namespace {

using namespace tofmat;

// The budget (docs/numerics.md): |fixed - float| <= kAbs + kRel |float|.
// (The squared residuals in Q8 steps: an element's square is off by up to
// |r| 2^-8 steps^2 of a score term r^2 / 2v, about 1e-4 of it; the basis in
// Q14 moves the fit by beta 2^-15.)
constexpr double kAbs = 1e-2, kRel = 2e-4;

std::shared_ptr<const ExemplarTable> real_table() {
  return std::make_shared<const ExemplarTable>(ExemplarTable::from_npy_dir(tofmat_test::db_dir(), 600.0, 1200.0));
}

// The table as the fixed path holds it, in mm: what the float reference must see to be compared.
std::shared_ptr<const ExemplarTable> dequantised(const FixedSessionClassifier& f) {
  const CompactTable& ct = f.compact();
  const ExemplarTable& t = f.reference().table();
  std::vector<float> values(t.values().size());
  for (std::size_t c = 0; c < ct.n_candidates(); ++c) {
    const std::uint32_t m = ct.candidates()[c];
    for (std::uint32_t r = 0; r < t.n_rows(); ++r) {
      for (std::uint32_t b = 0; b < t.n_bins(); ++b) {
        const float orig = t.material_values(m)[r * t.n_bins() + b];
        values[m * t.elements_per_material() + r * t.n_bins() + b] =
            std::isnan(orig) ? orig : static_cast<float>(ct.values(c)[r * ct.padded_bins() + b] * ct.step_mm());
      }
    }
  }
  return std::make_shared<const ExemplarTable>(t.materials(), t.rows(), t.bins(), std::move(values));
}

std::vector<float> quantised(std::vector<float> q, double step) {
  for (float& x : q) {
    if (!std::isnan(x)) x = static_cast<float>(std::clamp(std::nearbyint(x / step), -32767.0, 32767.0) * step);
  }
  return q;
}

// Sweeps of `length` bins of material m in a new session: offsets, the material's noise, outliers.
std::vector<float> session_sweep(const ExemplarTable& t, std::size_t m, std::uint32_t length, std::mt19937& rng) {
  std::normal_distribution<double> unit(0.0, 1.0);
  std::uniform_int_distribution<std::uint32_t> start(0, t.n_bins() - length);
  const std::uint32_t s = start(rng);
  std::vector<float> q(t.elements_per_material(), std::nanf(""));
  if (t.valid_count(m) == 0) return q;
  const double offset[2] = {2.27 * unit(rng), 0.73 * unit(rng)};
  for (std::uint32_t r = 0; r < t.n_rows(); ++r) {
    for (std::uint32_t b = s; b < s + length; ++b) {
      const float c = t.material_values(m)[r * t.n_bins() + b];
      if (std::isnan(c)) continue;
      double v = c + offset[r] + 0.4 * unit(rng);
      if (unit(rng) > 2.2) v += 15.0 * unit(rng);  // an outlier bin now and then
      q[r * t.n_bins() + b] = static_cast<float>(v);
    }
  }
  return q;
}

struct Setting {
  const char* name;
  SessionPrior prior;
};

std::vector<Setting> settings(const ExemplarTable& t) {
  std::vector<Setting> out;
  out.push_back({"tuned", SessionPrior::tuned(t)});
  SessionPrior gauss = SessionPrior::tuned(t);
  gauss.huber_k = std::numeric_limits<double>::infinity();
  gauss.drift2_sd_mm = 0.0;
  out.push_back({"gaussian, one drift term", gauss});
  SessionPrior hard = SessionPrior::tuned(t);
  hard.huber_k = 1.5;
  hard.iterations = 5;
  hard.floor_mm = 0.1;
  out.push_back({"hard huber", hard});
  SessionPrior none = SessionPrior::tuned(t);
  none.offset_sd_mm = {0.0, 0.0};
  none.drift1_sd_mm = none.drift2_sd_mm = 0.0;
  out.push_back({"no nuisance term", none});
  return out;
}

void expect_close(const Classification& fixed, const Classification& ref, const std::string& what, double rel = kRel) {
  ASSERT_EQ(fixed.ranking.size(), ref.ranking.size()) << what;
  // Compare by material: a near tie may swap two neighbours.
  for (const Match& r : ref.ranking) {
    const auto it =
        std::find_if(fixed.ranking.begin(), fixed.ranking.end(), [&](const Match& f) { return f.index == r.index; });
    ASSERT_NE(it, fixed.ranking.end()) << what;
    EXPECT_LE(std::fabs(it->distance - r.distance), kAbs + rel * std::fabs(r.distance))
        << what << " material " << r.index << ": fixed " << it->distance << ", float " << r.distance;
    EXPECT_EQ(it->valid, r.valid) << what;
    EXPECT_NEAR(it->fit, r.fit, kAbs + rel * std::fabs(r.fit)) << what;
  }
}

TEST(FixedSessionClassifier, FollowsTheFloatReferenceOnSessionSweepsWithinTheBudget) {
  ASSERT_DB_PRESENT();
  const auto table = real_table();
  std::mt19937 rng(11);
  double worst = 0.0;
  int same = 0, total = 0;
  for (const auto& s : settings(*table)) {
    const FixedSessionClassifier fixed(table, s.prior);
    const auto deq = dequantised(fixed);
    const SessionClassifier ref(deq, s.prior, fixed.reference().noise_mm());
    for (std::uint32_t length : {1u, 3u, 10u, 30u, 100u, 200u}) {
      for (std::size_t m = 0; m < table->n_materials(); m += 4) {
        auto q = quantised(session_sweep(*table, m, length, rng), fixed.compact().step_mm());
        if (std::none_of(q.begin(), q.end(), [](float x) { return !std::isnan(x); })) continue;  // all missing there
        const auto a = fixed.classify(q.data(), q.size());
        const auto b = ref.classify(q.data(), q.size());
        expect_close(a, b, std::string(s.name) + ", " + std::to_string(length) + " bins");
        for (std::size_t i = 0; i < b.ranking.size(); ++i) {
          const auto& r = b.ranking[i];
          const auto it =
              std::find_if(a.ranking.begin(), a.ranking.end(), [&](const Match& f) { return f.index == r.index; });
          worst = std::max(worst, std::fabs(it->distance - r.distance) / (1.0 + std::fabs(r.distance)));
        }
        same += a.best().index == b.best().index;
        ++total;
      }
    }
  }
  EXPECT_EQ(same, total);
  RecordProperty("worst_relative", std::to_string(worst));
  std::printf("worst |fixed - float| / (1 + |float|): %.3g over %d queries\n", worst, total);
}

TEST(FixedSessionClassifier, StiffCases) {
  ASSERT_DB_PRESENT();
  const auto table = real_table();
  const SessionPrior tuned = SessionPrior::tuned(*table);
  const FixedSessionClassifier fixed(table, tuned);
  const auto deq = dequantised(fixed);
  const SessionClassifier ref(deq, tuned, fixed.reference().noise_mm());
  const double step = fixed.compact().step_mm();
  const std::size_t cork = static_cast<std::size_t>(table->index_of("cork"));
  std::vector<float> q(table->elements_per_material(), std::nanf(""));
  // One element.
  q[57] = table->material_values(cork)[57];
  auto one = quantised(q, step);
  expect_close(fixed.classify(one.data(), one.size()), ref.classify(one.data(), one.size()), "one element");
  // A sweep saturating the int16 range: 32767 steps, every element an outlier of every candidate.
  for (std::size_t i = 0; i < 100; ++i) q[i] = q[200 + i] = static_cast<float>(40000.0 * step);
  auto sat = quantised(q, step);
  // (Scores of 2.5e5, every element a far outlier: the outliers' weights move
  // the fit of a quantised basis; within 5e-4 of the score, never a label.)
  expect_close(fixed.classify(sat.data(), sat.size()), ref.classify(sat.data(), sat.size()), "saturated", 5e-4);
  // The curve itself: residuals of zero.
  std::vector<float> exact(table->material_values(cork), table->material_values(cork) + table->elements_per_material());
  auto ex = quantised(exact, step);
  const auto c = fixed.classify(ex.data(), ex.size());
  expect_close(c, ref.classify(ex.data(), ex.size()), "the curve itself");
  EXPECT_EQ(table->materials()[c.best().index], "cork");
}

// The session learner's scales in one call: each scale's scores those of a
// matcher of its own scaled prior to the bit (the same order, distances, fits
// and counts), over settings, lengths, a candidate subset, the table's holes
// and both kernels; a scale not asked for is left empty.
TEST(FixedSessionClassifier, ScoresUnderEveryScaleAsEachScaledMatcherDoesToTheBit) {
  ASSERT_DB_PRESENT();
  const auto table = real_table();
  const std::vector<double> scales{0.0, 0.25, 1.0, 2.0, 4.0};
  std::mt19937 rng(23);
  int queries = 0;
  for (const auto& s : settings(*table)) {
    for (const FixedKernel kernel : {FixedKernel::kBest, FixedKernel::kScalar}) {
      for (const std::vector<std::uint32_t>& candidates : {std::vector<std::uint32_t>{}, {2, 5, 11, 17, 23}}) {
        const FixedSessionClassifier all(table, s.prior, {}, candidates, kernel, scales);
        EXPECT_EQ(all.scales(), scales);
        std::vector<FixedSessionClassifier> each;
        each.reserve(scales.size());
        for (const double x : scales)
          each.emplace_back(table, scaled(s.prior, x), std::vector<double>{}, candidates, kernel);
        std::vector<Classification> kept;  // (classify_scaled into it, call after call)
        for (std::uint32_t length : {1u, 3u, 10u, 30u, 100u, 200u}) {
          for (std::size_t m = 0; m < table->n_materials(); m += 7) {
            const auto q = session_sweep(*table, m, length, rng);
            if (std::none_of(q.begin(), q.end(), [](float x) { return !std::isnan(x); })) continue;
            std::vector<bool> wanted(scales.size(), true);
            wanted[1] = length % 2 == 0;  // (some calls leave a scale out)
            std::vector<Classification> got;
            try {
              got = all.classify_scaled(q.data(), q.size(), wanted);
            } catch (const std::invalid_argument&) {  // no candidate shares an element: each says so too
              EXPECT_THROW(each[0].classify(q.data(), q.size()), std::invalid_argument);
              continue;
            }
            ASSERT_EQ(got.size(), scales.size());
            // Unranked (for a mixture): the same matches in candidates() order.
            const std::vector<Classification> unranked = all.classify_scaled(q.data(), q.size(), wanted, false);
            ASSERT_EQ(unranked.size(), scales.size());
            // Into a kept vector (last filled under other flags), the fits as chi-square statistics:
            // the same matches, and each statistic's deviate the fit.
            all.classify_scaled(q.data(), q.size(), wanted, kept, false, false);
            ASSERT_EQ(kept.size(), scales.size());
            for (std::size_t j = 0; j < scales.size(); ++j) {
              ASSERT_EQ(kept[j].ranking.size(), unranked[j].ranking.size()) << j;
              for (std::size_t i = 0; i < kept[j].ranking.size(); ++i) {
                const Match &a = kept[j].ranking[i], &b = unranked[j].ranking[i];
                EXPECT_EQ(a.index, b.index) << j;
                EXPECT_EQ(a.distance, b.distance) << j;
                EXPECT_EQ(a.valid, b.valid) << j;
                EXPECT_GE(a.fit, 0.0) << j;
                EXPECT_EQ(chi_square_deviate(a.fit, a.valid), b.fit) << j;
              }
            }
            for (std::size_t j = 0; j < scales.size(); ++j) {
              Classification sorted = unranked[j];
              std::vector<std::ptrdiff_t> order;  // each match's place among candidates()
              for (const Match& match : sorted.ranking) {
                const auto& c = all.candidates();
                order.push_back(std::find(c.begin(), c.end(), match.index) - c.begin());
              }
              EXPECT_TRUE(std::is_sorted(order.begin(), order.end())) << j;
              if (!wanted[j]) {
                EXPECT_TRUE(sorted.ranking.empty()) << j;
                continue;
              }
              rank(sorted);
              ASSERT_EQ(sorted.ranking.size(), got[j].ranking.size()) << j;
              for (std::size_t i = 0; i < sorted.ranking.size(); ++i) {
                EXPECT_EQ(sorted.ranking[i].index, got[j].ranking[i].index) << j;
                EXPECT_EQ(sorted.ranking[i].distance, got[j].ranking[i].distance) << j;
                EXPECT_EQ(sorted.ranking[i].fit, got[j].ranking[i].fit) << j;
              }
            }
            for (std::size_t j = 0; j < scales.size(); ++j) {
              const std::string what = std::string(s.name) + ", scale " + std::to_string(scales[j]) + ", " +
                                       std::to_string(length) + " bins";
              if (!wanted[j]) {
                EXPECT_TRUE(got[j].ranking.empty()) << what;
                continue;
              }
              const auto want = each[j].classify(q.data(), q.size());
              ASSERT_EQ(got[j].ranking.size(), want.ranking.size()) << what;
              for (std::size_t i = 0; i < want.ranking.size(); ++i) {
                EXPECT_EQ(got[j].ranking[i].index, want.ranking[i].index) << what;
                EXPECT_EQ(got[j].ranking[i].distance, want.ranking[i].distance) << what;
                EXPECT_EQ(got[j].ranking[i].fit, want.ranking[i].fit) << what;
                EXPECT_EQ(got[j].ranking[i].valid, want.ranking[i].valid) << what;
              }
            }
            ++queries;
          }
        }
        // The prior's own matcher is unchanged by the scales it holds.
        const auto q = session_sweep(*table, 3, 30, rng);
        const auto a = all.classify(q.data(), q.size());
        const auto b = FixedSessionClassifier(table, s.prior, {}, candidates, kernel).classify(q.data(), q.size());
        ASSERT_EQ(a.ranking.size(), b.ranking.size());
        for (std::size_t i = 0; i < a.ranking.size(); ++i) EXPECT_EQ(a.ranking[i].distance, b.ranking[i].distance);
      }
    }
  }
  EXPECT_GT(queries, 100);
  const FixedSessionClassifier two(table, SessionPrior::tuned(*table), {}, {}, FixedKernel::kBest, {0.0, 1.0});
  std::vector<float> q(table->elements_per_material(), std::nanf(""));
  q[40] = 1.0f;
  EXPECT_THROW(two.classify_scaled(q.data(), q.size(), {true}), std::invalid_argument);  // a flag per scale
  EXPECT_TRUE(FixedSessionClassifier(table, SessionPrior::tuned(*table)).scales().empty());
  EXPECT_THROW(FixedSessionClassifier(table, SessionPrior::tuned(*table), {}, {}, FixedKernel::kBest, {1.0, -1.0}),
               std::invalid_argument);
  EXPECT_THROW(FixedSessionClassifier(table, SessionPrior::tuned(*table), {}, {}, FixedKernel::kBest,
                                      {std::numeric_limits<double>::infinity()}),
               std::invalid_argument);
}

TEST(FixedSessionClassifier, TheFloatReferencesErrors) {
  ASSERT_DB_PRESENT();
  const auto table = real_table();
  const FixedSessionClassifier fixed(table, SessionPrior::tuned(*table), {}, {3, 1});
  EXPECT_EQ(fixed.candidates(), (std::vector<std::uint32_t>{1, 3}));
  std::vector<float> q(table->elements_per_material(), std::nanf(""));
  EXPECT_THROW(fixed.classify(q.data(), q.size()), std::invalid_argument);  // nothing valid
  EXPECT_THROW(fixed.classify(q.data(), 7), std::invalid_argument);         // wrong size
  q[0] = std::numeric_limits<float>::infinity();
  EXPECT_THROW(fixed.classify(q.data(), q.size()), std::invalid_argument);
  SessionPrior bad = SessionPrior::tuned(*table);
  bad.iterations = 0;
  EXPECT_THROW(FixedSessionClassifier(table, bad), std::invalid_argument);
  EXPECT_THROW(FixedSessionClassifier(table, SessionPrior::tuned(*table), {}, {99}), std::invalid_argument);
}

}  // namespace
