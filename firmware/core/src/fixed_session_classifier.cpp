// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FixedSessionClassifier: the session-robust matcher with integer per-element
// work (fixed_session_classifier.hpp); the bounds of every integer are noted
// where it is computed (at most 65535 elements in a row).
#include "tofmat/core/fixed_session_classifier.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>

#include "fixed_session_kernel.hpp"
#include "session_solve.hpp"

namespace tofmat {

namespace {

using session_detail::kBasisBits;
using session_detail::kFitBits;
using session_detail::kMaxCoefficient;
using session_detail::kNoThreshold;
using session_detail::kWeightBits;
using session_detail::SessionElements;
using session_detail::SessionPassSums;

constexpr double kLog2Pi = 1.8378770664093453;  // log(2 pi)
constexpr int kMaxTerms = kSessionMaxTerms;

// Exact powers of two (a multiplication by one is exact; std::ldexp is a library call).
constexpr double kBasisUnit = 1.0 / (1 << kBasisBits);                  // Q14 -> 1
constexpr double kBasisUnit2 = kBasisUnit * kBasisUnit;                 // Q28 -> 1
constexpr double kFitScale = static_cast<double>(1 << kFitBits);        // 1 -> Q8
constexpr double kFitUnit = 1.0 / kFitScale;                            // Q8 -> 1
constexpr double kSquareUnit = kFitUnit * kFitUnit;                     // Q16 (a Q8 value squared) -> 1
constexpr double kWeightBasisUnit = kBasisUnit / (1 << kWeightBits);    // Q15 x Q14 -> 1
constexpr double kWeightBasisUnit2 = kBasisUnit2 / (1 << kWeightBits);  // Q15 x Q28 -> 1

// Nearest integer (ties to even: one instruction on aarch64 and x86-64), held within +-limit.
std::int64_t clamp_round(double x, std::int64_t limit) {
  if (!(x < static_cast<double>(limit))) return limit;  // (NaN too: never from a solve of a positive definite P)
  if (x <= -static_cast<double>(limit)) return -limit;
  return static_cast<std::int64_t>(std::nearbyint(x));
}

using Gram = std::array<std::array<std::int64_t, kMaxTerms>, kMaxTerms>;  // lower triangle used

// A row's bins that the query holds, their basis values and Gram matrix
// (|a a| <= 2^28 over at most 2^16 elements: within 2^44).
struct QueryRow {
  std::vector<std::uint32_t> bins;
  std::array<std::vector<std::int32_t>, kMaxTerms> f;  // their fit basis (Q31)
  std::vector<std::uint32_t> at;                       // their elements in the compact table's padded layout
  std::vector<std::int32_t> q;                         // the quantised query there
  std::array<std::vector<std::int32_t>, kMaxTerms> a;
  Gram gram{};
  void clear() {  // (keeps the vectors' storage)
    bins.clear();
    at.clear();
    q.clear();
    for (auto& v : f) v.clear();
    for (auto& v : a) v.clear();
    gram = Gram{};
  }
};

// score()'s buffers, one set a thread.
struct ScoreScratch {
  std::vector<QueryRow> rows;
  std::vector<std::int32_t> e;
  std::array<std::vector<std::int32_t>, kMaxTerms> a_held, f_held;
  std::vector<double> total, energy, det_root, log_det;  // per prior (score() says what they hold)
};

// One row's nuisance fit of a candidate under one prior: the reweighting
// passes, and what the score takes from the last (its sums, the fit's penalty
// and P's Cholesky diagonal, whose product over a candidate's rows gives
// their log det P with one log: cholesky_log_det). Instantiated for each count of terms, so that the K x K
// work is unrolled (K = the basis's terms, 1..3).
struct RowFit {
  // The last pass's sums. (Whole: copying three of its fields out instead cost more than it saved.)
  session_detail::SessionPassSums sums;
  double penalty = 0.0;
  std::array<double, kMaxTerms> diagonal{};
};

template <int K>
RowFit fit_row(const SessionElements& x, const session_detail::NormalSums& all, const std::array<double, kMaxTerms>& pv,
               double v, int iterations, bool huber, std::int32_t threshold, session_detail::SessionPassFn pass) {
  RowFit out;
  session_detail::NormalSums normal = all;
  std::array<double, kMaxTerms> beta{}, diagonal{};
  std::array<std::int32_t, kMaxTerms> B{};
  session_detail::SessionPassSums& sums = out.sums;
  for (int it = 0; it < iterations; ++it) {
    std::array<std::array<double, kMaxTerms>, kMaxTerms> P{};
    std::array<double, kMaxTerms> rhs{};
    for (int s = 0; s < K; ++s) {
      rhs[s] = static_cast<double>(normal.h[s]) * kWeightBasisUnit / v;
      for (int t = 0; t <= s; ++t) {
        const double g = static_cast<double>(normal.G[s][t]) * kWeightBasisUnit2 / v;
        P[s][t] = g;
        P[t][s] = g;
      }
      P[s][s] += 1.0 / pv[s];
    }
    session_detail::cholesky_factor_solve(P, K, rhs, beta, diagonal);
    for (int s = 0; s < K; ++s) B[s] = static_cast<std::int32_t>(clamp_round(beta[s] * kFitScale, kMaxCoefficient));
    // The residuals of this fit give the data term and the next pass's weights.
    const bool last = !huber || it + 1 == iterations;
    sums = pass(x, K, B.data(), threshold, !last);
    if (last) break;
    // No outlier in the first pass: the next system is this one (all weights 1), the fit the same.
    if (it == 0 && sums.n_beyond == 0) break;
    session_detail::NormalSums next = all;
    for (int s = 0; s < K; ++s) {
      next.h[s] -= sums.shortfall.h[s];
      for (int t = 0; t <= s; ++t) next.G[s][t] -= sums.shortfall.G[s][t];
    }
    if (next == normal) break;  // the same system again would give the same fit
    normal = next;
  }
  out.diagonal = diagonal;
  for (int s = 0; s < K; ++s) out.penalty += 0.5 * beta[s] * beta[s] / pv[s];
  return out;
}

using RowFitFn = RowFit (*)(const SessionElements&, const session_detail::NormalSums&,
                            const std::array<double, kMaxTerms>&, double, int, bool, std::int32_t,
                            session_detail::SessionPassFn);

RowFitFn row_fit(int k) {
  switch (k) {
    case 1: return fit_row<1>;
    case 2: return fit_row<2>;
    default: return fit_row<3>;
  }
}

}  // namespace

FixedSessionClassifier::FixedSessionClassifier(const std::shared_ptr<const ExemplarTable>& table, SessionPrior prior,
                                               std::vector<double> noise_mm, std::vector<std::uint32_t> candidates,
                                               FixedKernel kernel, const std::vector<double>& scales)
    : reference_(table, std::move(prior), std::move(noise_mm), std::move(candidates)),
      eq12_(table, reference_.candidates(), FixedKernel::kScalar),
      kernel_(kernel),
      scales_(scales) {
  const std::uint32_t bins = table->n_bins(), rows = table->n_rows();
  const int k = reference_.terms();
  for (int t = 0; t < k; ++t) {
    basis_[static_cast<std::size_t>(t)].resize(bins);
    fit_basis_[static_cast<std::size_t>(t)].resize(bins);
  }
  for (std::uint32_t j = 0; j < bins; ++j) {
    for (int t = 0; t < k; ++t) {
      const double a = session_basis(j, bins, reference_.degree(t));
      basis_[static_cast<std::size_t>(t)][j] = static_cast<std::int32_t>(std::lround(std::ldexp(a, kBasisBits)));
      // |P1|, |P2| < 1 at a bin's centre: within int32 in Q31 (held there all the same).
      fit_basis_[static_cast<std::size_t>(t)][j] =
          static_cast<std::int32_t>(std::clamp(std::nearbyint(std::ldexp(a, 31)), -2147483647.0, 2147483647.0));
    }
  }
  const SessionPrior& p = reference_.prior();
  const double step = eq12_.compact().step_mm(), step2 = step * step;
  const bool huber = std::isfinite(p.huber_k);
  for (const std::uint32_t index : reference_.candidates()) {
    for (std::uint32_t r = 0; r < rows; ++r) {
      const double sigma = p.noise_scale * reference_.noise_mm()[index * rows + r];
      const double v_mm = sigma * sigma + p.floor_mm * p.floor_mm;
      RowNoise n;
      n.v = v_mm / step2;
      n.sd = std::sqrt(n.v);
      n.log_norm = 0.5 * (kLog2Pi + std::log(v_mm));
      n.threshold =
          huber ? static_cast<std::int32_t>(clamp_round(p.huber_k * n.sd * kFitScale, kNoThreshold)) : kNoThreshold;
      noise_.push_back(n);
    }
  }
  prior_ = prior_steps(reference_);
  for (const double scale : scales_) {
    // (the scaled prior's terms, variances and their logs as its own matcher derives them: the
    // scores are then that matcher's to the bit; a scale > 0 keeps the prior's terms, 0 has none)
    const SessionClassifier r(table, scaled(p, scale), reference_.noise_mm(), reference_.candidates());
    scaled_.push_back(prior_steps(r));
  }
}

FixedSessionClassifier::PriorSteps FixedSessionClassifier::prior_steps(const SessionClassifier& reference) const {
  const double step = eq12_.compact().step_mm(), step2 = step * step;
  const int k = reference.terms();
  if (k != 0 && k != reference_.terms())  // (never: scaling keeps every term or none)
    throw std::logic_error("fixed session matcher: a scaled prior with other nuisance terms");
  PriorSteps out;
  out.terms = k;
  for (std::uint32_t r = 0; r < reference.table().n_rows(); ++r) {
    std::array<double, kMaxTerms> pv{};
    for (int t = 0; t < k; ++t)
      pv[static_cast<std::size_t>(t)] = reference.prior_var(r)[static_cast<std::size_t>(t)] / step2;
    out.var.push_back(pv);
    out.log_det.push_back(reference.log_det_prior(r) - k * std::log(step2));
  }
  return out;
}

Classification FixedSessionClassifier::classify(const float* query, std::size_t n) const {
  std::vector<Classification> out(1);
  score(query, n, {&prior_}, out);
  return std::move(out[0]);
}

std::vector<Classification> FixedSessionClassifier::classify_scaled(const float* query, std::size_t n,
                                                                    const std::vector<bool>& wanted,
                                                                    bool ranked) const {
  std::vector<Classification> out;
  classify_scaled(query, n, wanted, out, ranked);
  return out;
}

void FixedSessionClassifier::classify_scaled(const float* query, std::size_t n, const std::vector<bool>& wanted,
                                             std::vector<Classification>& out, bool ranked, bool deviates) const {
  if (wanted.size() != scales_.size()) {
    throw std::invalid_argument("fixed session matcher: " + std::to_string(wanted.size()) + " flags for " +
                                std::to_string(scales_.size()) + " scales");
  }
  thread_local std::vector<const PriorSteps*> priors;  // (kept: a frame's label allocates nothing here)
  priors.assign(scales_.size(), nullptr);
  for (std::size_t j = 0; j < scales_.size(); ++j)
    if (wanted[j]) priors[j] = &scaled_[j];
  out.resize(scales_.size());
  score(query, n, priors, out, ranked, deviates);
}

void FixedSessionClassifier::score(const float* query, std::size_t n, const std::vector<const PriorSteps*>& priors,
                                   std::vector<Classification>& out, bool ranked, bool deviates) const {
  const FixedClassifier::Prepared p = eq12_.prepare(query, n);  // validated, quantised
  const CompactTable& ct = eq12_.compact();
  const ExemplarTable& table = reference_.table();
  const SessionPrior& prior = reference_.prior();  // (its noise model and reweighting: every scale's)
  const std::uint32_t rows = ct.n_rows();
  const std::size_t pb = ct.padded_bins();
  const int k = reference_.terms();  // the basis's terms: a prior has them all or none
  const auto K = static_cast<std::size_t>(k);
  const std::size_t n_priors = priors.size();
  bool moments_wanted = false;  // some prior fits terms
  for (const PriorSteps* ps : priors) moments_wanted = moments_wanted || (ps != nullptr && ps->terms > 0);
  const bool huber = std::isfinite(prior.huber_k);
  const double hk = prior.huber_k;
  const auto has = [](const std::uint8_t* bits, std::size_t i) { return ((bits[i / 8] >> (i % 8)) & 1u) != 0; };
  const bool vector = kernel_ == FixedKernel::kBest;  // NEON on aarch64; the scalar kernels elsewhere
  const session_detail::SessionPassFn pass_ = session_detail::session_pass(vector);
  const session_detail::SessionMomentsFn moments_ = session_detail::session_moments(vector);
  const RowFitFn fit_ = row_fit(k);  // (used only for a prior with terms: k >= 1)

  // This thread's buffers, kept from query to query (a handheld frame is one
  // query or two: no allocation once they have grown).
  thread_local ScoreScratch scratch;
  // What does not depend on the candidate: per row the query's bins, their basis and Gram matrix.
  std::vector<QueryRow>& qrows = scratch.rows;
  qrows.resize(rows);
  for (std::uint32_t r = 0; r < rows; ++r) {
    QueryRow& qr = qrows[r];
    qr.clear();
    const std::size_t lo = p.first[r] * kCompactBlock, hi = p.last[r] * kCompactBlock;
    const std::size_t span = hi > lo ? hi - lo : 0;  // (a row the query leaves empty has last < first)
    qr.bins.reserve(span);                           // (one allocation each, not one per doubling)
    qr.at.reserve(span);
    qr.q.reserve(span);
    for (std::size_t b = lo; b < hi && b < table.n_bins(); ++b) {
      const std::size_t i = static_cast<std::size_t>(r) * pb + b;
      if (!has(p.mask.data(), i)) continue;
      qr.bins.push_back(static_cast<std::uint32_t>(b));
      qr.at.push_back(static_cast<std::uint32_t>(i));
      qr.q.push_back(p.q[i]);
    }
    for (std::size_t t = 0; t < K; ++t) {
      qr.a[t].reserve(qr.bins.size());
      for (const std::uint32_t b : qr.bins) qr.a[t].push_back(basis_[t][b]);
      qr.f[t].reserve(qr.bins.size());
      for (const std::uint32_t b : qr.bins) qr.f[t].push_back(fit_basis_[t][b]);
      qr.a[t].resize(session_detail::session_padded(qr.bins.size()));  // (the kernels' padding)
      qr.f[t].resize(session_detail::session_padded(qr.bins.size()));
    }
    for (std::size_t j = 0; j < qr.bins.size(); ++j)
      for (std::size_t s = 0; s < K; ++s)
        for (std::size_t t = 0; t <= s; ++t) qr.gram[s][t] += std::int64_t{qr.a[s][j]} * qr.a[t][j];
  }

  std::vector<std::int32_t>& e = scratch.e;  // query - candidate, steps: |e| <= 65534
  // The bases of the compared bins when some are missing.
  std::array<std::vector<std::int32_t>, kMaxTerms>&a_held = scratch.a_held, &f_held = scratch.f_held;
  for (std::size_t j = 0; j < n_priors; ++j) {
    out[j].ranking.clear();
    if (priors[j] != nullptr) out[j].ranking.reserve(ct.n_candidates());
  }
  // (raw pointers into the scratch, held in locals: through the vectors, every
  // opaque call in the loop below would make the compiler load them again)
  for (std::vector<double>* v : {&scratch.total, &scratch.energy, &scratch.det_root, &scratch.log_det})
    v->resize(n_priors);
  double* const total = scratch.total.data();    // per prior, over the candidate's rows
  double* const energy = scratch.energy.data();  // (the same)
  // Per prior, the candidate's rows' Cholesky diagonals: their product (kept
  // while it is a normal number) and the logs of those it could not hold,
  // so that log det P costs one log a candidate, not one a row.
  double* const det_root = scratch.det_root.data();
  double* const log_det = scratch.log_det.data();
  for (std::size_t c = 0; c < ct.n_candidates(); ++c) {
    const std::uint32_t index = ct.candidates()[c];
    const std::int16_t* values = ct.values(c);
    const std::uint8_t* valid = ct.validity(c);
    std::fill(total, total + n_priors, 0.0);
    std::fill(energy, energy + n_priors, 0.0);
    std::fill(det_root, det_root + n_priors, 1.0);
    std::fill(log_det, log_det + n_priors, 0.0);
    std::uint32_t compared = 0;
    for (std::uint32_t r = 0; r < rows; ++r) {
      const QueryRow& qr = qrows[r];
      const RowNoise& noise = noise_[c * rows + r];
      const double v = noise.v;
      const std::size_t asked = qr.bins.size();
      const std::size_t base = static_cast<std::size_t>(r) * pb;
      // The compared elements: the query's bins the candidate holds. A bin it
      // lacks leaves the Gram matrix (exact: integers).
      Gram gram = qr.gram;
      SessionElements x;
      bool holes = false;
      if (valid != nullptr) {
        const std::size_t block0 = base / kCompactBlock;
        for (std::size_t blk = block0 + p.first[r]; blk < block0 + p.last[r]; ++blk)
          holes = holes || (p.mask[blk] & ~valid[blk]) != 0;
      }
      if (!holes) {
        e.resize(session_detail::session_padded(asked));
        for (std::size_t j = 0; j < asked; ++j) e[j] = qr.q[j] - std::int32_t{values[qr.at[j]]};
        for (std::size_t t = 0; t < K; ++t) {
          x.a[t] = qr.a[t].data();
          x.f[t] = qr.f[t].data();
        }
      } else {
        e.clear();
        for (std::size_t t = 0; t < K; ++t) {
          a_held[t].clear();
          f_held[t].clear();
        }
        for (std::size_t j = 0; j < asked; ++j) {
          const std::size_t i = qr.at[j];
          if (!has(valid, i)) {
            for (std::size_t s = 0; s < K; ++s)
              for (std::size_t t = 0; t <= s; ++t) gram[s][t] -= std::int64_t{qr.a[s][j]} * qr.a[t][j];
            continue;
          }
          e.push_back(qr.q[j] - std::int32_t{values[i]});
          for (std::size_t t = 0; t < K; ++t) {
            a_held[t].push_back(qr.a[t][j]);
            f_held[t].push_back(qr.f[t][j]);
          }
        }
        const std::size_t padded = session_detail::session_padded(e.size());
        for (std::size_t t = 0; t < K; ++t) {
          a_held[t].resize(padded);
          f_held[t].resize(padded);
          x.a[t] = a_held[t].data();
          x.f[t] = f_held[t].data();
        }
      }
      x.constant = k > 0 && reference_.degree(0) == 0;
      x.n = holes ? e.size() : asked;
      e.resize(session_detail::session_padded(x.n));
      x.e = e.data();
      const std::size_t nr = x.n;
      compared += static_cast<std::uint32_t>(nr);
      // The first pass weighs every element 1 (2^15): its sums are the Gram
      // matrix's and sum e a (|e a| <= 2^30 over 2^16 elements: within 2^46),
      // whatever the prior.
      session_detail::NormalSums all;
      if (moments_wanted) {
        moments_(x, k, all.h);
        for (std::size_t s = 0; s < K; ++s) {
          all.h[s] *= std::int64_t{1} << kWeightBits;
          for (std::size_t t = 0; t <= s; ++t) all.G[s][t] = gram[s][t] * (std::int64_t{1} << kWeightBits);
        }
      }
      for (std::size_t j = 0; j < n_priors; ++j) {
        if (priors[j] == nullptr) continue;
        const PriorSteps& ps = *priors[j];
        // The data term: inliers' squares in Q8 (saturating), outliers' magnitudes in Q16.
        const auto data_term = [&](std::uint64_t squares, std::int64_t beyond, std::int64_t n_beyond) {
          double d = static_cast<double>(squares) * (kSquareUnit / 2.0) / v;
          if (huber)
            d += hk * (static_cast<double>(beyond) * kFitUnit) / noise.sd -
                 0.5 * hk * hk * static_cast<double>(n_beyond);
          return d;
        };
        double data = 0.0, penalty = 0.0, logdet = 0.0;
        if (ps.terms > 0) {  // (the sums read where the fit left them, not copied)
          const RowFit fit = fit_(x, all, ps.var[r], v, prior.iterations, huber, noise.threshold, pass_);
          data = data_term(fit.sums.squares, fit.sums.beyond, fit.sums.n_beyond);
          penalty = fit.penalty;
          logdet = ps.log_det[r];
          double product = det_root[j];
          for (int t = 0; t < k; ++t) product *= fit.diagonal[static_cast<std::size_t>(t)];
          if (std::isnormal(product)) {
            det_root[j] = product;
          } else {  // (never with a prior's variances in their range: kept exact all the same)
            log_det[j] += session_detail::cholesky_log_det(fit.diagonal, k);
          }
        } else {
          const std::int32_t none[kMaxTerms] = {};
          const SessionPassSums sums = pass_(x, 0, none, noise.threshold, false);
          data = data_term(sums.squares, sums.beyond, sums.n_beyond);
        }
        energy[j] += data + penalty;
        total[j] += data + static_cast<double>(nr) * noise.log_norm + penalty + 0.5 * logdet +
                    static_cast<double>(asked - nr) * (0.5 + noise.log_norm);
      }
    }
    if (compared == 0) continue;
    for (std::size_t j = 0; j < n_priors; ++j) {
      if (priors[j] == nullptr) continue;
      // (half of log det P over the rows: log of the diagonals' product, half the logs kept apart)
      const double t = priors[j]->terms > 0 ? total[j] + (std::log(det_root[j]) + 0.5 * log_det[j]) : total[j];
      const double q = 2.0 * energy[j];  // (the chi-square statistic)
      out[j].ranking.push_back(Match{index, t, compared, deviates ? chi_square_deviate(q, compared) : q});
    }
  }
  for (std::size_t j = 0; j < n_priors; ++j) {
    if (priors[j] == nullptr) continue;
    if (ranked) {
      rank(out[j]);
    } else if (out[j].ranking.empty()) {  // (rank()'s error, without its sort)
      throw std::invalid_argument("query shares no valid element with any candidate material");
    }
  }
}

}  // namespace tofmat
