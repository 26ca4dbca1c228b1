// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// SessionLearner: the mixture of session priors of session_learner.hpp and
// the weights it learns from finished sweeps.
#include "tofmat/core/session_learner.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "tofmat/core/fixed_session_classifier.hpp"
#include "tofmat/core/session_classifier.hpp"

namespace tofmat {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// log sum exp of v[0..n), -inf for no finite term.
double log_sum_exp(const double* v, std::size_t n) {
  double top = -kInf;
  for (std::size_t i = 0; i < n; ++i) top = std::max(top, v[i]);
  if (!std::isfinite(top)) return top;
  double s = 0.0;
  for (std::size_t i = 0; i < n; ++i) s += std::exp(v[i] - top);
  return top + std::log(s);
}
double log_sum_exp(const std::vector<double>& v) { return log_sum_exp(v.data(), v.size()); }

// How many bins of a query of n_rows rows have a value in any row.
std::uint32_t bins_covered(const float* query, std::size_t n, std::uint32_t n_rows) {
  const std::size_t bins = n / n_rows;
  std::uint32_t covered = 0;
  for (std::size_t b = 0; b < bins; ++b) {
    for (std::size_t r = 0; r < n_rows; ++r) {
      if (std::isfinite(query[r * bins + b])) {
        ++covered;
        break;
      }
    }
  }
  return covered;
}

// classify()'s buffers, one set a thread, kept from query to query: a
// frame's label then allocates only the ranking it returns. (classify()
// says what each holds.)
struct ClassifyScratch {
  std::vector<std::size_t> scored_as;
  std::vector<double> log_w;
  std::vector<float> shifted;
  std::vector<bool> weighed, scored, as_is, moved;
  std::vector<Classification> by_scale, plain;
  std::vector<double> neg_score, terms;
  std::vector<std::uint32_t> order;
  std::vector<std::size_t> place, in_ranking;
};

}  // namespace

void SessionLearning::validate() const {
  if (scales.empty()) throw std::invalid_argument("session learning: give at least one scale");
  for (std::size_t k = 0; k < scales.size(); ++k) {
    if (!(scales[k] >= 0.0) || std::isinf(scales[k]))
      throw std::invalid_argument("session learning: a scale must be finite and >= 0");
    if (k > 0 && !(scales[k] > scales[k - 1]))
      throw std::invalid_argument("session learning: the scales must be increasing");
  }
  if (!(forget > 0.0 && forget <= 1.0)) throw std::invalid_argument("session learning: forget must be in (0, 1]");
  if (!(evidence_cap > 0.0) || std::isinf(evidence_cap))
    throw std::invalid_argument("session learning: evidence_cap must be finite and > 0");
  if (!prior_weights.empty()) {
    if (prior_weights.size() != scales.size()) {
      throw std::invalid_argument("session learning: " + std::to_string(prior_weights.size()) + " prior weights for " +
                                  std::to_string(scales.size()) + " scales");
    }
    for (double w : prior_weights) {
      if (!(w > 0.0) || std::isinf(w))
        throw std::invalid_argument("session learning: a prior weight must be finite and > 0");
    }
  }
  for (std::size_t t = 0; t < long_sweeps.size(); ++t) {
    const LongSweep& tier = long_sweeps[t];
    if (tier.bins == 0) throw std::invalid_argument("session learning: a long sweep has at least 1 bin");
    if (std::find(scales.begin(), scales.end(), tier.scale) == scales.end())
      throw std::invalid_argument("session learning: a long sweep's scale must be one of the scales");
    if (t > 0 && !(tier.bins > long_sweeps[t - 1].bins && tier.scale < long_sweeps[t - 1].scale))
      throw std::invalid_argument("session learning: long sweeps go up in bins and down in scale");
  }
}

namespace {

// Per-scale scorers as one ScaledScorer (validated by count first).
SessionLearner::ScaledScorer each_scale(const SessionLearning& settings, std::vector<SessionLearner::Scorer> scorers) {
  if (scorers.size() != settings.scales.size()) {
    throw std::invalid_argument("session learning: " + std::to_string(scorers.size()) + " scorers for " +
                                std::to_string(settings.scales.size()) + " scales");
  }
  return [scorers = std::move(scorers)](const float* q, std::size_t n, const std::vector<bool>& wanted,
                                        std::vector<Classification>& out) {
    out.resize(scorers.size());
    for (std::size_t k = 0; k < scorers.size(); ++k) {
      if (wanted[k]) {
        out[k] = scorers[k](q, n);
      } else {
        out[k].ranking.clear();
      }
    }
  };
}

// Each entry's material, as the table numbers them.
std::vector<std::uint32_t> materials_of(const ExemplarTable& table) {
  std::vector<std::uint32_t> out(table.n_materials());
  for (std::size_t m = 0; m < out.size(); ++m) out[m] = table.material_id(m);
  return out;
}

}  // namespace

SessionLearner::SessionLearner(const SessionLearning& settings, std::vector<Scorer> scorers, std::uint32_t n_rows,
                               std::shared_ptr<const SessionClassifier> offsets, std::vector<std::uint32_t> materials)
    : SessionLearner(settings, each_scale(settings, std::move(scorers)), n_rows, std::move(offsets),
                     std::move(materials)) {}

SessionLearner::SessionLearner(SessionLearning settings, ScaledScorer scorer, std::uint32_t n_rows,
                               std::shared_ptr<const SessionClassifier> offsets, std::vector<std::uint32_t> materials,
                               bool statistic_fits)
    : settings_(std::move(settings)),
      scorer_(std::move(scorer)),
      n_rows_(n_rows),
      materials_(std::move(materials)),
      statistic_fits_(statistic_fits) {
  settings_.validate();
  {
    std::vector<std::uint32_t> sorted = materials_;
    std::sort(sorted.begin(), sorted.end());
    one_each_ = std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end();
  }
  if (!scorer_) throw std::invalid_argument("session learning: no scorer");
  if (n_rows_ == 0) throw std::invalid_argument("session learning: a query has at least one row");
  if (offsets && settings_.learn_offsets) {
    if (offsets->table().n_rows() != n_rows_)
      throw std::invalid_argument("session learning: the offsets' session matcher has another count of rows");
    offsets_ = std::make_unique<SessionOffsets>(std::move(offsets), settings_.forget);
  }
  for (const SessionLearning::LongSweep& tier : settings_.long_sweeps) {
    const auto at = std::find(settings_.scales.begin(), settings_.scales.end(), tier.scale);
    long_tiers_.emplace_back(tier.bins, static_cast<std::size_t>(at - settings_.scales.begin()));
  }
  log_prior_.assign(settings_.scales.size(), 0.0);
  for (std::size_t k = 0; k < settings_.prior_weights.size(); ++k) log_prior_[k] = std::log(settings_.prior_weights[k]);
  log_weight_ = log_prior_;
}

std::shared_ptr<SessionLearner> SessionLearner::make(const std::shared_ptr<const ExemplarTable>& table,
                                                     const SessionPrior& prior, bool fixed_point,
                                                     const std::vector<double>& noise_mm,
                                                     const std::vector<std::uint32_t>& candidates,
                                                     SessionLearning settings) {
  settings.validate();
  if (fixed_point) {
    auto c = std::make_shared<const FixedSessionClassifier>(table, prior, noise_mm, candidates, FixedKernel::kBest,
                                                            settings.scales);
    // (unranked: the learner ranks the mixture, not each scale; the fits as statistics: it keeps one a candidate)
    ScaledScorer scorer = [c](const float* q, std::size_t n, const std::vector<bool>& wanted,
                              std::vector<Classification>& out) {
      c->classify_scaled(q, n, wanted, out, false, false);
    };
    // (the fixed matcher's float reference is at the calibration's prior: it learns the offsets)
    std::shared_ptr<const SessionClassifier> reference(c, &c->reference());
    return std::make_shared<SessionLearner>(std::move(settings), std::move(scorer), table->n_rows(),
                                            std::move(reference), materials_of(*table), true);
  }
  std::vector<Scorer> scorers;
  for (double s : settings.scales) {
    auto c = std::make_shared<const SessionClassifier>(table, scaled(prior, s), noise_mm, candidates);
    scorers.emplace_back([c](const float* q, std::size_t n) { return c->classify(q, n); });
  }
  auto reference = std::make_shared<const SessionClassifier>(table, prior, noise_mm, candidates);
  return std::make_shared<SessionLearner>(std::move(settings), std::move(scorers), table->n_rows(),
                                          std::move(reference), materials_of(*table));
}

SessionLearner::Scored SessionLearner::classify(const float* query, std::size_t n, bool every_scale) const {
  const std::size_t k_count = settings_.scales.size();
  if (n % n_rows_ != 0) {
    throw std::invalid_argument("session learning: a query of " + std::to_string(n) + " elements is not " +
                                std::to_string(n_rows_) + " rows");
  }
  // (scored_as[k]: whose scores scale k enters the mixture with; itself but in a long sweep, where
  // it is no wider than the scale of the last tier the query reaches)
  std::size_t widest = k_count - 1;
  bool pins_offsets = false;  // scored as it is: it places its own session
  if (!long_tiers_.empty() || settings_.pins_offsets_bins > 0) {
    const std::uint32_t covered = bins_covered(query, n, n_rows_);
    for (const auto& [bins, index] : long_tiers_) {
      if (covered < bins) break;
      widest = index;
    }
    pins_offsets = settings_.pins_offsets_bins > 0 && covered >= settings_.pins_offsets_bins;
  }
  thread_local ClassifyScratch scratch;
  std::vector<std::size_t>& scored_as = scratch.scored_as;
  scored_as.resize(k_count);
  for (std::size_t k = 0; k < k_count; ++k) scored_as[k] = std::min(k, widest);
  std::vector<double>& log_w = scratch.log_w;
  std::vector<float>& shifted =
      scratch.shifted;  // the query less the learned offsets (empty: nothing learned, or not shifted)
  shifted.clear();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    log_w = log_weight_;
    if (offsets_) {
      const std::vector<float>& shift = offsets_->shift();
      if (shift.size() != n) {
        throw std::invalid_argument("session learning: a query of " + std::to_string(n) +
                                    " elements, the table's have " + std::to_string(shift.size()));
      }
      if (!pins_offsets && std::any_of(shift.begin(), shift.end(), [](float v) { return v != 0.0F; })) {
        shifted.assign(query, query + n);
        for (std::size_t i = 0; i < n; ++i) shifted[i] -= shift[i];
      }
    }
  }
  const double norm = log_sum_exp(log_w);
  for (double& w : log_w) w -= norm;
  double heaviest = -kInf;
  for (double w : log_w) heaviest = std::max(heaviest, w);
  std::vector<bool>& weighed = scratch.weighed;  // enters the mixture
  std::vector<bool>& scored = scratch.scored;    // its scorer runs
  weighed.assign(k_count, false);
  scored.assign(k_count, false);
  for (std::size_t k = 0; k < k_count; ++k) {
    weighed[k] = log_w[k] >= heaviest - kNegligibleNats;
    if (weighed[k]) scored[scored_as[k]] = true;
  }
  if (every_scale) std::fill(scored.begin(), scored.end(), true);

  // Scale 0 is the table's own session, offsets and all: it scores the query as it is; the other
  // scales score it less the learned offsets (session_offsets.hpp).
  const auto score = [&](const float* q, const std::vector<bool>& wanted, std::vector<Classification>& into) {
    scorer_(q, n, wanted, into);
    if (into.size() != k_count) throw std::logic_error("session learning: a scorer gave another count of scales");
  };
  std::vector<Classification>& by_scale = scratch.by_scale;
  if (shifted.empty()) {
    score(query, scored, by_scale);
  } else {
    std::vector<bool>&as_is = scratch.as_is, &moved = scratch.moved;
    as_is.assign(k_count, false);
    moved = scored;
    for (std::size_t k = 0; k < k_count; ++k) {
      if (settings_.scales[k] == 0.0) {
        as_is[k] = scored[k];
        moved[k] = false;
      }
    }
    const auto any = [](const std::vector<bool>& v) { return std::find(v.begin(), v.end(), true) != v.end(); };
    if (any(moved)) {
      score(shifted.data(), moved, by_scale);
    } else {
      by_scale.resize(k_count);
      for (Classification& c : by_scale) c.ranking.clear();
    }
    if (any(as_is)) {
      std::vector<Classification>& plain = scratch.plain;
      score(query, as_is, plain);
      for (std::size_t k = 0; k < k_count; ++k)
        if (as_is[k]) std::swap(by_scale[k].ranking, plain[k].ranking);  // (both keep storage for the next query)
    }
  }
  std::size_t first = k_count;  // the first scored scale: its ranking gives the candidates' order
  for (std::size_t k = 0; k < k_count && first == k_count; ++k)
    if (scored[k]) first = k;

  // Per candidate (as the first scale ranks them), its score under every scale.
  const std::size_t m_count = by_scale[first].ranking.size();
  Scored out;
  // (the evidence only for a sweep to learn from: a frame's label needs none of it)
  if (every_scale) out.evidence.assign(k_count, -kInf);
  // -D_k(m) at [k * m_count + i], i in the first scale's order
  std::vector<double>& neg_score = scratch.neg_score;
  neg_score.assign(k_count * m_count, -kInf);
  std::vector<std::uint32_t>& order = scratch.order;
  order.clear();
  std::uint32_t top_index = 0;
  for (const Match& m : by_scale[first].ranking) {
    order.push_back(m.index);
    top_index = std::max(top_index, m.index);
  }
  // Each candidate's place in that order (kNone: not a candidate), and per scale where it sits in that scale's ranking.
  constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
  std::vector<std::size_t>& place = scratch.place;
  place.assign(std::size_t{top_index} + 1, kNone);
  for (std::size_t i = 0; i < m_count; ++i) place[order[i]] = i;
  std::vector<std::size_t>& in_ranking = scratch.in_ranking;  // (as neg_score)
  in_ranking.assign(k_count * m_count, kNone);
  const auto mismatch = [] {
    return std::logic_error("session learning: the scales' scorers rank different candidates");
  };
  // Each candidate's share of its material's prior weight, as a log (0 for a
  // material of one candidate): log(n_most / n), n its material's candidates
  // in the ranking, n_most the most any material has. (Relative: a common
  // factor moves every scale's evidence alike; tables of as many exemplars a
  // material as each other give 0 throughout.)
  std::vector<double> log_share;  // (a sweep to learn from only: the evidence and the offsets' shares)
  if (every_scale) log_share.assign(m_count, 0.0);
  if (!materials_.empty()) {
    for (std::size_t i = 0; i < m_count; ++i) {
      if (order[i] >= materials_.size())
        throw std::invalid_argument("session learning: candidate " + std::to_string(order[i]) + " has no material");
    }
  }
  if (!one_each_ && every_scale) {
    std::vector<std::uint32_t> of(m_count);
    std::uint32_t top_material = 0;
    for (std::size_t i = 0; i < m_count; ++i) {
      of[i] = materials_[order[i]];
      top_material = std::max(top_material, of[i]);
    }
    std::vector<std::uint32_t> members(std::size_t{top_material} + 1, 0);
    for (const std::uint32_t g : of) ++members[g];
    const std::uint32_t most = *std::max_element(members.begin(), members.end());
    for (std::size_t i = 0; i < m_count; ++i)
      if (members[of[i]] != most) log_share[i] = std::log(static_cast<double>(most) / members[of[i]]);
  }
  for (std::size_t k = 0; k < k_count; ++k) {
    if (!scored[k]) continue;
    if (by_scale[k].ranking.size() != m_count) throw mismatch();
    double* const neg_k = neg_score.data() + k * m_count;
    std::size_t* const in_k = in_ranking.data() + k * m_count;
    for (std::size_t j = 0; j < m_count; ++j) {
      const Match& m = by_scale[k].ranking[j];
      const std::size_t at = m.index <= top_index ? place[m.index] : kNone;
      if (at == kNone || in_k[at] != kNone) throw mismatch();
      neg_k[at] = -m.distance;
      in_k[at] = j;
    }
    if (!every_scale) continue;
    if (one_each_) {
      out.evidence[k] = log_sum_exp(neg_k, m_count);
    } else {
      std::vector<double> shared(neg_k, neg_k + m_count);
      for (std::size_t i = 0; i < m_count; ++i) shared[i] += log_share[i];
      out.evidence[k] = log_sum_exp(shared);
    }
  }
  out.mixture.ranking.reserve(m_count);
  std::vector<double>& terms = scratch.terms;
  terms.resize(k_count);
  for (std::size_t i = 0; i < m_count; ++i) {
    std::size_t likeliest = first;
    double top = -kInf;
    for (std::size_t k = 0; k < k_count; ++k) {
      terms[k] = weighed[k] ? log_w[k] + neg_score[scored_as[k] * m_count + i] : -kInf;
      if (terms[k] > top) {
        top = terms[k];
        likeliest = scored_as[k];
      }
    }
    Match m = by_scale[likeliest].ranking[in_ranking[likeliest * m_count + i]];
    m.distance = -log_sum_exp(terms);
    if (statistic_fits_) m.fit = chi_square_deviate(m.fit, m.valid);
    out.mixture.ranking.push_back(m);
  }
  std::sort(out.mixture.ranking.begin(), out.mixture.ranking.end(), [](const Match& a, const Match& b) {
    return a.distance < b.distance || (a.distance == b.distance && a.index < b.index);
  });
  if (every_scale && offsets_ && !out.mixture.ranking.empty()) {
    // Each candidate's posterior share under the mixture (the materials equally likely, a
    // material's candidates sharing its weight), relative to the largest.
    const auto weighed_distance = [&](const Match& m) { return m.distance - log_share[place[m.index]]; };
    double best = kInf;
    for (const Match& m : out.mixture.ranking) best = std::min(best, weighed_distance(m));
    std::vector<std::pair<std::uint32_t, double>> shares;
    for (const Match& m : out.mixture.ranking) {
      const double share = std::exp(best - weighed_distance(m));
      if (share >= SessionOffsets::kNegligibleShare) shares.emplace_back(m.index, share);
    }
    std::lock_guard<std::mutex> lock(mutex_);
    out.offsets = offsets_->evidence(query, n, shares);
  }
  return out;
}

void SessionLearner::learn(const Scored& sweep) {
  if (sweep.evidence.size() != log_weight_.size())
    throw std::invalid_argument("session learning: a sweep's evidence has " + std::to_string(sweep.evidence.size()) +
                                " scales, the learner " + std::to_string(log_weight_.size()));
  double best = -kInf;
  for (double e : sweep.evidence) {
    if (std::isnan(e) || e == -kInf) {
      throw std::invalid_argument("session learning: a sweep to learn from must be scored at every scale");
    }
    best = std::max(best, e);
  }
  if (!std::isfinite(best)) return;  // nothing to learn from
  std::lock_guard<std::mutex> lock(mutex_);
  double top = -kInf;
  for (std::size_t k = 0; k < log_weight_.size(); ++k) {
    const double e = sweep.evidence[k];
    const double moved = std::isfinite(e) ? std::max(e - best, -settings_.evidence_cap) : -settings_.evidence_cap;
    log_weight_[k] = settings_.forget * log_weight_[k] + moved;
    top = std::max(top, log_weight_[k]);
  }
  for (double& w : log_weight_) w -= top;  // (kept near 0: the weights are relative)
  if (offsets_) offsets_->learn(sweep.offsets);
  ++sweeps_;
}

void SessionLearner::reset() {
  std::lock_guard<std::mutex> lock(mutex_);
  log_weight_ = log_prior_;
  if (offsets_) offsets_->reset();
  sweeps_ = 0;
}

SessionLearner::State SessionLearner::state() const {
  State s;
  s.scales = settings_.scales;
  std::vector<double> log_w;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    log_w = log_weight_;
    s.sweeps = sweeps_;
    if (offsets_) {
      for (const auto& t : offsets_->terms_mm()) {
        s.offsets_mm.push_back(t[0]);
        s.drift_mm.push_back({t[1], t[2]});
      }
    }
  }
  const double norm = log_sum_exp(log_w);
  for (std::size_t k = 0; k < log_w.size(); ++k) {
    s.weights.push_back(std::exp(log_w[k] - norm));
    s.scale += s.weights.back() * s.scales[k];
  }
  return s;
}

}  // namespace tofmat
