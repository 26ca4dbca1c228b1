// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session-learning matcher (session_learner.hpp): the mixture's score in
// closed form over scorers with known scores, the weights' update (evidence,
// cap, forgetting, reset), the scales it skips, and on a small table of real
// session classifiers: an unmoved session settles on scale 0, a moved one on a
// wide scale, and each then labels a sweep the other way of matching gets wrong;
// and the session's offsets it learns (session_offsets.hpp): the posterior
// mean, forgetting, clipping, and twins told apart in a session that moved.
#include "tofmat/core/session_learner.hpp"

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

// A scorer that ranks candidates 0..n-1 with the given scores (lower first), counting its calls.
SessionLearner::Scorer fixed_scores(const std::vector<double>& scores, int* calls = nullptr) {
  return [scores, calls](const float*, std::size_t) {
    if (calls) ++*calls;
    Classification c;
    for (std::uint32_t i = 0; i < scores.size(); ++i) c.ranking.push_back({i, scores[i], 4, 0.1 * i});
    std::sort(c.ranking.begin(), c.ranking.end(),
              [](const Match& a, const Match& b) { return a.distance < b.distance; });
    return c;
  };
}

SessionLearning two_scales(double forget = 1.0, double cap = 10.0) {
  SessionLearning s;
  s.scales = {0.0, 1.0};
  s.long_sweeps = {{20, 1.0}};
  s.forget = forget;
  s.evidence_cap = cap;
  s.prior_weights = {};  // equal
  return s;
}

const float kQuery[1] = {0.0f};

TEST(SessionLearner, TheMixturesScoreIsMinusTheLogOfTheWeightedLikelihoods) {
  // Scale 0 prefers candidate 0 strongly, scale 1 candidate 1 mildly.
  SessionLearner l(two_scales(), {fixed_scores({1.0, 5.0}), fixed_scores({3.0, 2.0})}, 1);
  const auto s = l.classify(kQuery, 1);
  ASSERT_EQ(s.mixture.ranking.size(), 2u);
  const double d0 = -std::log(0.5 * std::exp(-1.0) + 0.5 * std::exp(-3.0));
  const double d1 = -std::log(0.5 * std::exp(-5.0) + 0.5 * std::exp(-2.0));
  EXPECT_EQ(s.mixture.best().index, 0u);
  EXPECT_NEAR(s.mixture.ranking[0].distance, d0, 1e-12);
  EXPECT_NEAR(s.mixture.ranking[1].distance, d1, 1e-12);
  // A candidate's fit is that of its likeliest scale (candidate 1: scale 1's).
  EXPECT_DOUBLE_EQ(s.mixture.ranking[1].fit, 0.1);
  // A frame's label carries no evidence; a sweep to learn from does, and the same mixture.
  EXPECT_TRUE(s.evidence.empty());
  EXPECT_THROW(l.learn(s), std::invalid_argument);
  const auto sweep = l.classify(kQuery, 1, true);
  EXPECT_NEAR(sweep.evidence[0], std::log(std::exp(-1.0) + std::exp(-5.0)), 1e-12);
  EXPECT_NEAR(sweep.evidence[1], std::log(std::exp(-3.0) + std::exp(-2.0)), 1e-12);
  ASSERT_EQ(sweep.mixture.ranking.size(), 2u);
  EXPECT_EQ(sweep.mixture.ranking[0].distance, s.mixture.ranking[0].distance);
  EXPECT_EQ(sweep.mixture.ranking[1].distance, s.mixture.ranking[1].distance);
}

TEST(SessionLearner, EvidenceMovesTheWeightsCappedForgottenAndResetBySession) {
  // Scale 1 explains every sweep e^2 better than scale 0 does.
  SessionLearner l(two_scales(0.5, 10.0), {fixed_scores({4.0, 9.0}), fixed_scores({2.0, 7.0})}, 1);
  EXPECT_DOUBLE_EQ(l.state().weights[0], 0.5);
  const auto sweep = l.classify(kQuery, 1, true);
  const double e = sweep.evidence[1] - sweep.evidence[0];  // 2 nats
  EXPECT_NEAR(e, 2.0, 1e-12);
  l.learn(sweep);
  auto st = l.state();
  EXPECT_EQ(st.sweeps, 1u);
  EXPECT_NEAR(st.weights[1] / st.weights[0], std::exp(2.0), 1e-9);
  EXPECT_NEAR(st.scale, st.weights[1], 1e-12);
  // Forgetting 0.5: the log ratio after n sweeps is 2 (1 + 0.5 + ... ), at most 4.
  for (int i = 0; i < 30; ++i) l.learn(sweep);
  st = l.state();
  EXPECT_NEAR(std::log(st.weights[1] / st.weights[0]), 4.0, 1e-6);
  l.reset();
  st = l.state();
  EXPECT_EQ(st.sweeps, 0u);
  EXPECT_DOUBLE_EQ(st.weights[0], 0.5);

  // One sweep moves a weight by at most the cap.
  SessionLearner capped(two_scales(1.0, 3.0), {fixed_scores({50.0, 90.0}), fixed_scores({2.0, 7.0})}, 1);
  capped.learn(capped.classify(kQuery, 1, true));
  st = capped.state();
  EXPECT_NEAR(std::log(st.weights[1] / st.weights[0]), 3.0, 1e-9);
}

TEST(SessionLearner, ANegligibleScaleIsNotScoredUnlessEveryScaleIsAskedFor) {
  int calls0 = 0, calls1 = 0;
  SessionLearner l(two_scales(1.0, 40.0), {fixed_scores({60.0, 70.0}, &calls0), fixed_scores({2.0, 7.0}, &calls1)}, 1);
  l.learn(l.classify(kQuery, 1, true));  // scale 0 now ~58 nats down (under the 30 of kNegligibleNats)
  calls0 = calls1 = 0;
  const auto s = l.classify(kQuery, 1);
  EXPECT_EQ(calls0, 0);
  EXPECT_EQ(calls1, 1);
  EXPECT_TRUE(s.evidence.empty());
  EXPECT_NEAR(s.mixture.best().distance, 2.0, 1e-9);
  // Such a classification cannot be learned from: it lacks a scale's evidence.
  EXPECT_THROW(l.learn(s), std::invalid_argument);
  l.classify(kQuery, 1, true);
  EXPECT_EQ(calls0, 1);
}

TEST(SessionLearner, BadSettingsAreRefusedByName) {
  SessionLearning s;
  s.scales = {};
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.scales = {0.0, 0.0};
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.scales = {-1.0, 1.0};
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.scales = {0.0, 1.0};
  s.long_sweeps = {};
  s.forget = 0.0;
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.forget = 0.9;
  s.evidence_cap = std::nan("");
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.evidence_cap = 10.0;
  EXPECT_THROW(s.validate(), std::invalid_argument);  // the default's six prior weights, two scales
  s.prior_weights = {1.0, 0.0};
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.prior_weights = {1.0, 3.0};
  EXPECT_NO_THROW(s.validate());  // no long sweeps
  s.long_sweeps = {{20, 0.5}};    // not one of the scales
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.long_sweeps = {{0, 1.0}};  // no bins
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.long_sweeps = {{20, 1.0}, {20, 0.0}};  // not up in bins
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.long_sweeps = {{20, 0.0}, {40, 1.0}};  // not down in scale
  EXPECT_THROW(s.validate(), std::invalid_argument);
  s.long_sweeps = {{20, 1.0}, {40, 0.0}};
  EXPECT_NO_THROW(s.validate());
  s.long_sweeps = {{20, 1.0}};
  EXPECT_NO_THROW(s.validate());
  EXPECT_NO_THROW(SessionLearning{}.validate());                                     // the defaults
  EXPECT_THROW(SessionLearner(s, {fixed_scores({1.0})}, 1), std::invalid_argument);  // 1 scorer, 2 scales
  EXPECT_THROW(SessionLearner(s, {fixed_scores({1.0}), fixed_scores({1.0})}, 0), std::invalid_argument);
  SessionLearner two_rows(s, {fixed_scores({1.0}), fixed_scores({1.0})}, 2);
  const float three[3] = {0.0f, 0.0f, 0.0f};
  EXPECT_THROW(two_rows.classify(three, 3), std::invalid_argument);  // 3 elements are not 2 rows
  SessionLearner l(s, {fixed_scores({1.0}), fixed_scores({1.0})}, 1);
  SessionLearner::Scored wrong;
  wrong.evidence = {0.0, 0.0, 0.0};
  EXPECT_THROW(l.learn(wrong), std::invalid_argument);
  EXPECT_THROW(scaled(SessionPrior{}, -1.0), std::invalid_argument);
}

TEST(SessionLearner, ASessionStartsAndRestartsFromThePriorWeights) {
  SessionLearning s = two_scales();
  s.prior_weights = {1.0, 3.0};
  SessionLearner l(s, {fixed_scores({1.0, 5.0}), fixed_scores({3.0, 2.0})}, 1);
  const auto fresh = l.state();
  EXPECT_NEAR(fresh.weights[0], 0.25, 1e-12);
  EXPECT_NEAR(fresh.weights[1], 0.75, 1e-12);
  const auto sc = l.classify(kQuery, 1, true);
  EXPECT_NEAR(sc.mixture.ranking[0].distance, -std::log(0.25 * std::exp(-1.0) + 0.75 * std::exp(-3.0)), 1e-12);
  l.learn(sc);
  EXPECT_GT(l.state().weights[0], 0.25);  // scale 0 explains the sweep better (evidence -0.98 against -1.69)
  l.reset();
  EXPECT_NEAR(l.state().weights[0], 0.25, 1e-12);
  EXPECT_EQ(l.state().sweeps, 0u);
}

TEST(SessionLearner, ALongSweepScoresTheWideScalesAsItsTiersScale) {
  SessionLearning s;
  s.scales = {0.0, 1.0, 2.0};
  s.prior_weights = {};
  s.long_sweeps = {{3, 1.0}, {4, 0.0}};
  int calls1 = 0, calls2 = 0;
  // Scale 2 alone prefers candidate 1.
  SessionLearner l(s, {fixed_scores({4.0, 6.0}), fixed_scores({2.0, 3.0}, &calls1), fixed_scores({5.0, 1.0}, &calls2)},
                   1);
  const float nan = std::nanf("");
  const float short_sweep[5] = {0.0f, 0.0f, nan, nan, nan};     // 2 bins
  const float long_sweep[5] = {0.0f, nan, 0.0f, 0.0f, nan};     // 3 bins
  const float longer_sweep[5] = {0.0f, nan, 0.0f, 0.0f, 0.0f};  // 4 bins
  const auto by_own = l.classify(short_sweep, 5);
  EXPECT_EQ(calls2, 1);
  EXPECT_EQ(by_own.mixture.best().index, 1u);
  EXPECT_NEAR(by_own.mixture.best().distance, -std::log((std::exp(-6.0) + std::exp(-3.0) + std::exp(-1.0)) / 3.0),
              1e-12);
  const auto as_one = l.classify(long_sweep, 5);
  EXPECT_EQ(calls2, 1);  // scale 2 enters as scale 1 and is not scored
  EXPECT_EQ(as_one.mixture.best().index, 0u);
  EXPECT_NEAR(as_one.mixture.best().distance, -std::log((std::exp(-4.0) + 2.0 * std::exp(-2.0)) / 3.0), 1e-12);
  // The next tier: every scale enters as scale 0, the only one scored.
  const int calls1_before = calls1;
  const auto as_zero = l.classify(longer_sweep, 5);
  EXPECT_EQ(calls1, calls1_before);
  EXPECT_EQ(calls2, 1);
  EXPECT_NEAR(as_zero.mixture.best().distance, 4.0, 1e-12);
  // Learning still weighs scale 2 by its own evidence.
  const auto every = l.classify(long_sweep, 5, true);
  EXPECT_EQ(calls2, 2);
  EXPECT_NEAR(every.evidence[2], std::log(std::exp(-5.0) + std::exp(-1.0)), 1e-12);
  EXPECT_EQ(every.mixture.best().index, 0u);
}

// Two materials 1.2 mm apart on row 0 (equal on row 1), 40 bins, noise 0.2 mm.
struct Twins {
  std::shared_ptr<const ExemplarTable> table;
  Twins() {
    const std::uint32_t bins = 40;
    std::vector<float> v(2 * 2 * bins);
    for (std::uint32_t j = 0; j < bins; ++j) {
      const float trend = 0.05f * static_cast<float>(j);
      v[0 * 2 * bins + j] = 10.0f + trend;  // material a, row 0
      v[0 * 2 * bins + bins + j] = 3.0f;    // row 1
      v[1 * 2 * bins + j] = 11.2f + trend;  // material b, row 0
      v[1 * 2 * bins + bins + j] = 3.0f;
    }
    table = std::make_shared<const ExemplarTable>(std::vector<std::string>{"a", "b"},
                                                  std::vector<RowSpec>{{16, 120}, {80, 120}},
                                                  BinSpec{600.0, 10.0, bins}, std::move(v));
  }
  // Material m's 10-bin sweep from bin 15, moved by `offset` on row 0, with noise.
  std::vector<float> sweep(int m, double offset, std::mt19937& rng) const {
    std::normal_distribution<double> noise(0.0, 0.2);
    const std::uint32_t bins = table->n_bins();
    std::vector<float> q(2 * bins, std::nanf(""));
    for (std::uint32_t j = 15; j < 25; ++j) {
      q[j] = static_cast<float>(table->material_values(static_cast<std::size_t>(m))[j] + offset + noise(rng));
      q[bins + j] = static_cast<float>(3.0 + noise(rng));
    }
    return q;
  }
};

// Six finished sweeps, a and b in turn, of a session that moved row 0 by `offset` mm.
void learn_six_sweeps(SessionLearner& l, const Twins& t, double offset, std::mt19937& rng) {
  for (int i = 0; i < 6; ++i) {
    const auto q = t.sweep(i % 2, offset, rng);
    l.learn(l.classify(q.data(), q.size(), true));
  }
}

SessionPrior twins_prior() {
  SessionPrior p;
  p.offset_sd_mm = {2.0, 0.5};
  p.drift1_sd_mm = p.drift2_sd_mm = 0.0;
  p.noise_scale = 0.0;
  p.floor_mm = 0.2;
  return p;
}

TEST(SessionLearner, AnUnmovedSessionSettlesOnScaleZeroAndTellsTwinsApart) {
  Twins t;
  for (bool fixed : {false, true}) {
    auto l = SessionLearner::make(t.table, twins_prior(), fixed);
    std::mt19937 rng(7);
    learn_six_sweeps(*l, t, 0.0, rng);
    const auto st = l->state();
    EXPECT_GT(st.weights[0], 0.8) << (fixed ? "fixed" : "float");
    EXPECT_LT(st.scale, 0.1);
    // The session did not move: a sweep of b is b, not a moved by 1.2 mm.
    int right = 0;
    for (int i = 0; i < 20; ++i) {
      const auto q = t.sweep(1, 0.0, rng);
      right += l->classify(q.data(), q.size()).mixture.best().index == 1;
    }
    EXPECT_EQ(right, 20) << (fixed ? "fixed" : "float");
  }
}

// A material's exemplars share its weight: a table holding a three times (three
// identical exemplars a@1, a@2, a@3) learns what the table holding it once
// learns from the same sweeps, weights and offsets alike; counted per entry,
// a's three copies would weigh it three times in every sweep's evidence.
TEST(SessionLearner, AMaterialWeighsTheSameHoweverManyExemplarsItHas) {
  Twins t;
  const std::uint32_t bins = t.table->n_bins();
  std::vector<float> v;
  for (int copy = 0; copy < 3; ++copy)
    v.insert(v.end(), t.table->material_values(0), t.table->material_values(0) + 2 * bins);
  v.insert(v.end(), t.table->material_values(1), t.table->material_values(1) + 2 * bins);
  const auto uneven = std::make_shared<const ExemplarTable>(std::vector<std::string>{"a@1", "a@2", "a@3", "b"},
                                                            std::vector<RowSpec>{{16, 120}, {80, 120}},
                                                            BinSpec{600.0, 10.0, bins}, std::move(v));
  for (bool fixed : {false, true}) {
    auto once = SessionLearner::make(t.table, twins_prior(), fixed);
    auto thrice = SessionLearner::make(uneven, twins_prior(), fixed);
    std::mt19937 rng(5);
    for (int i = 0; i < 6; ++i) {
      // a session that moved row 0 by 0.6 mm: half way to b, where the scales' evidence differs
      const auto q = t.sweep(i % 3 == 2 ? 1 : 0, 0.6, rng);
      const auto s1 = once->classify(q.data(), q.size(), true);
      const auto s3 = thrice->classify(q.data(), q.size(), true);
      ASSERT_EQ(s1.evidence.size(), s3.evidence.size());
      for (std::size_t k = 0; k + 1 < s1.evidence.size(); ++k)  // (differences: a common factor is no evidence)
        EXPECT_NEAR(s3.evidence[k] - s3.evidence.back(), s1.evidence[k] - s1.evidence.back(), 1e-9) << k;
      once->learn(s1);
      thrice->learn(s3);
    }
    const auto a = once->state(), b = thrice->state();
    for (std::size_t k = 0; k < a.weights.size(); ++k) EXPECT_NEAR(b.weights[k], a.weights[k], 1e-9) << k;
    ASSERT_EQ(a.offsets_mm.size(), b.offsets_mm.size());
    for (std::size_t r = 0; r < a.offsets_mm.size(); ++r) EXPECT_NEAR(b.offsets_mm[r], a.offsets_mm[r], 1e-9) << r;
    EXPECT_GT(std::abs(a.offsets_mm[0]), 0.05) << "the sweeps moved the offsets (else the test shows nothing)";
  }
  // A ranked index without a material is refused.
  SessionLearner bad(two_scales(),
                     std::vector<SessionLearner::Scorer>{fixed_scores({1, 2, 3}), fixed_scores({1, 2, 3})}, 1, nullptr,
                     {0, 0});
  EXPECT_THROW(bad.classify(kQuery, 1), std::invalid_argument);
}

TEST(SessionLearner, AMovedSessionSettlesOnAWideScaleWithoutLearningItsOffsets) {
  Twins t;
  SessionLearning weights_only;
  weights_only.learn_offsets = false;
  auto l = SessionLearner::make(t.table, twins_prior(), false, {}, {}, weights_only);
  std::mt19937 rng(11);
  // The session moved row 0 by 4 mm: no material explains a sweep without an offset.
  learn_six_sweeps(*l, t, 4.0, rng);
  const auto st = l->state();
  EXPECT_GT(st.scale, 1.0);
  EXPECT_LT(st.weights[0], 1e-6);
  EXPECT_EQ(st.sweeps, 6u);
  EXPECT_TRUE(st.offsets_mm.empty() && st.drift_mm.empty());
}

TEST(SessionLearner, LearnsWhereTheSessionMovedAndThenTellsTwinsApart) {
  // A session that moved row 0 by 2.4 mm: material a then reads as b moved by 1.2 mm, and a
  // matcher that only knows how far sessions move cannot tell them apart. Learned from sweeps of
  // both, the offset comes out and the twins separate again.
  Twins t;
  for (bool fixed : {false, true}) {
    const char* backend = fixed ? "fixed" : "float";
    auto l = SessionLearner::make(t.table, twins_prior(), fixed);
    std::mt19937 rng(5);
    for (int i = 0; i < 12; ++i) {
      const auto q = t.sweep(i % 2, 2.4, rng);
      l->learn(l->classify(q.data(), q.size(), true));
    }
    const auto st = l->state();
    ASSERT_EQ(st.offsets_mm.size(), 2u) << backend;
    ASSERT_EQ(st.drift_mm.size(), 2u) << backend;
    EXPECT_NEAR(st.offsets_mm[0], 2.4, 0.2) << backend;
    EXPECT_NEAR(st.offsets_mm[1], 0.0, 0.1) << backend;
    EXPECT_EQ(st.drift_mm[0][0], 0.0) << backend;  // (no drift term in this prior)
    int right = 0;
    for (int i = 0; i < 20; ++i) {
      const int m = i % 2;
      const auto q = t.sweep(m, 2.4, rng);
      right += l->classify(q.data(), q.size()).mixture.best().index == static_cast<std::uint32_t>(m);
    }
    EXPECT_EQ(right, 20) << backend;
    // A new session forgets where the last one was.
    l->reset();
    EXPECT_EQ(l->state().offsets_mm[0], 0.0) << backend;
  }
}

TEST(SessionLearner, ScaleZeroAndSweepsThatPinTheirOffsetsScoreTheQueryAsItIsTheOtherScalesLessTheLearnedOffsets) {
  Twins t;
  const SessionPrior prior = twins_prior();
  // pins_offsets: the bins from which a sweep is scored as it is (0: never); the first long-sweep
  // tier at 10 bins, below it, caps the scales without pinning the offsets.
  for (std::uint32_t pins_offsets : {20u, 0u}) {
    SessionLearning settings = two_scales(0.9);
    settings.long_sweeps = {{10, 1.0}};
    settings.pins_offsets_bins = pins_offsets;
    std::vector<float> seen(2, std::nanf(""));  // what each scale's scorer saw at row 0, bin 15
    std::vector<SessionLearner::Scorer> scorers;
    for (std::size_t k = 0; k < 2; ++k) {
      auto c = std::make_shared<const SessionClassifier>(t.table, scaled(prior, settings.scales[k]));
      scorers.emplace_back([c, k, &seen](const float* q, std::size_t n) {
        seen[k] = q[15];
        return c->classify(q, n);
      });
    }
    SessionLearner l(settings, std::move(scorers), 2, std::make_shared<const SessionClassifier>(t.table, prior));
    std::mt19937 rng(3);
    for (int i = 0; i < 8; ++i) {
      const auto q = t.sweep(i % 2, 2.4, rng);
      l.learn(l.classify(q.data(), q.size(), true));
    }
    const double learned = l.state().offsets_mm[0];
    ASSERT_GT(learned, 1.0) << pins_offsets;
    // A 10-bin sweep reaches the long-sweep tier and is still scored less the learned offsets.
    auto q = t.sweep(0, 2.4, rng);
    l.classify(q.data(), q.size(), true);
    EXPECT_EQ(seen[0], q[15]) << pins_offsets;
    EXPECT_NEAR(seen[1], q[15] - learned, 1e-5) << pins_offsets;
    // A 25-bin sweep (from bin 0) pins its own offsets: scored as it is at every scale, unless
    // no sweep pins them.
    for (std::uint32_t j = 0; j < 25; ++j) q[j] = t.table->material_values(0)[j] + 2.4f, q[40 + j] = 3.0f;
    l.classify(q.data(), q.size(), true);
    EXPECT_EQ(seen[0], q[15]) << pins_offsets;
    if (pins_offsets > 0)
      EXPECT_EQ(seen[1], q[15]);
    else
      EXPECT_NEAR(seen[1], q[15] - learned, 1e-5);
  }
}

TEST(SessionOffsets, TheMeanIsThePosteriorMeanOfTheSharedTermsAndForgets) {
  Twins t;
  SessionPrior p = twins_prior();
  auto reference = std::make_shared<const SessionClassifier>(t.table, p);
  SessionOffsets o(reference, 0.5);
  const std::uint32_t bins = t.table->n_bins();
  // Material a moved by 1 mm on row 0, every element, no noise: with n elements of variance v
  // and the prior sd 2 mm, the posterior mean is (n / v) / (n / v + 1 / 4) x 1 mm.
  std::vector<float> q(2 * bins, std::nanf(""));
  for (std::uint32_t j = 0; j < 10; ++j) {
    q[j] = t.table->material_values(0)[j] + 1.0f;
    q[bins + j] = 3.0f;
  }
  const auto e = o.evidence(q.data(), q.size(), {{0, 1.0}});
  const double v = 0.2 * 0.2, info = 10.0 / v;
  EXPECT_NEAR(e.lambda[0][0][0], info, 1e-9);
  EXPECT_NEAR(e.eta[0][0], info * 1.0, 1e-5);
  o.learn(e);
  EXPECT_NEAR(o.terms_mm()[0][0], info / (info + 0.25), 1e-6);
  EXPECT_NEAR(o.shift()[3], info / (info + 0.25), 1e-6);
  // A second sweep at 0 mm: the first counts half (forget 0.5).
  for (std::uint32_t j = 0; j < 10; ++j) q[j] = t.table->material_values(0)[j];
  o.learn(o.evidence(q.data(), q.size(), {{0, 1.0}}));
  EXPECT_NEAR(o.terms_mm()[0][0], 0.5 * info / (1.5 * info + 0.25), 1e-6);
  // Shares split the evidence, negligible ones are left out; none left: no evidence.
  const auto split = o.evidence(q.data(), q.size(), {{0, 0.5}, {1, 0.5}, {1, 1e-4}});
  EXPECT_NEAR(split.lambda[0][0][0], info, 1e-9);
  EXPECT_TRUE(o.evidence(q.data(), q.size(), {{0, 1e-4}}).empty());
  o.reset();
  EXPECT_EQ(o.terms_mm()[0][0], 0.0);
  EXPECT_EQ(o.shift()[3], 0.0f);
}

TEST(SessionOffsets, OneWildElementBarelyMovesTheMean) {
  Twins t;
  auto reference = std::make_shared<const SessionClassifier>(t.table, twins_prior());
  SessionOffsets o(reference, 1.0);
  const std::uint32_t bins = t.table->n_bins();
  std::vector<float> q(2 * bins, std::nanf(""));
  for (std::uint32_t j = 0; j < 10; ++j) q[j] = t.table->material_values(0)[j];
  q[4] += 1000.0f;  // a flying pixel's bin
  o.learn(o.evidence(q.data(), q.size(), {{0, 1.0}}));
  // Down-weighted by the robust fit to 3 sds' worth (0.6 mm of 10 elements' information).
  EXPECT_LT(std::fabs(o.terms_mm()[0][0]), 0.07);
  EXPECT_GT(o.terms_mm()[0][0], 0.0);
}

TEST(SessionOffsets, BadInputIsRefused) {
  Twins t;
  auto reference = std::make_shared<const SessionClassifier>(t.table, twins_prior());
  EXPECT_THROW(SessionOffsets(nullptr, 0.9), std::invalid_argument);
  EXPECT_THROW(SessionOffsets(reference, 0.0), std::invalid_argument);
  EXPECT_THROW(SessionOffsets(reference, 1.5), std::invalid_argument);
  SessionOffsets o(reference, 0.9);
  std::vector<float> q(2 * t.table->n_bins(), 1.0f);
  EXPECT_THROW(o.evidence(q.data(), q.size() - 1, {{0, 1.0}}), std::invalid_argument);
  EXPECT_THROW(o.evidence(q.data(), q.size(), {{7, 1.0}}), std::invalid_argument);
  SessionOffsets::Evidence wrong;
  wrong.lambda.resize(3);
  wrong.eta.resize(3);
  EXPECT_THROW(o.learn(wrong), std::invalid_argument);
}

}  // namespace
