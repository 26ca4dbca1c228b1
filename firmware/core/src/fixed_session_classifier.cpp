// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FixedSessionClassifier: the session-robust matcher with integer per-element
// work (fixed_session_classifier.hpp); the bounds of every integer are noted
// where it is computed (at most 65535 elements in a row).
#include "tofmat/core/fixed_session_classifier.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "session_solve.hpp"

namespace tofmat {

namespace {

constexpr double kLog2Pi = 1.8378770664093453;  // log(2 pi)
constexpr int kMaxTerms = kSessionMaxTerms;
constexpr int kBasisBits = 14;                                   // basis values in Q14: |a| <= 2^14
constexpr int kFitBits = 16;                                     // nuisance coefficients and residuals in Q16 steps
constexpr std::int64_t kMaxCoefficient = std::int64_t{1} << 40;  // |beta| <= 2^24 steps: far beyond any fit
constexpr std::int64_t kMaxThreshold = std::int64_t{1} << 60;    // beyond every residual: no outlier

// Exact powers of two (a multiplication by one is exact; std::ldexp is a library call).
constexpr double kBasisUnit = 1.0 / (1 << kBasisBits);            // Q14 -> 1
constexpr double kBasisUnit2 = kBasisUnit * kBasisUnit;           // Q28 -> 1
constexpr double kFitScale = static_cast<double>(1 << kFitBits);  // 1 -> Q16
constexpr double kFitUnit = 1.0 / kFitScale;                      // Q16 -> 1

// Nearest integer (ties to even: one instruction on aarch64 and x86-64), held within +-limit.
std::int64_t clamp_round(double x, std::int64_t limit) {
  if (!(x < static_cast<double>(limit))) return limit;  // (NaN too: never from a solve of a positive definite P)
  if (x <= -static_cast<double>(limit)) return -limit;
  return static_cast<std::int64_t>(std::nearbyint(x));
}

// a + b, held at UINT64_MAX instead of wrapping: a sum that large only says
// the candidate explains nothing.
std::uint64_t add_saturating(std::uint64_t a, std::uint64_t b) {
  return b > std::numeric_limits<std::uint64_t>::max() - a ? std::numeric_limits<std::uint64_t>::max() : a + b;
}

}  // namespace

FixedSessionClassifier::FixedSessionClassifier(const std::shared_ptr<const ExemplarTable>& table, SessionPrior prior,
                                               std::vector<double> noise_mm, std::vector<std::uint32_t> candidates)
    : reference_(table, std::move(prior), std::move(noise_mm), std::move(candidates)),
      eq12_(table, reference_.candidates(), FixedKernel::kScalar) {
  const std::uint32_t bins = table->n_bins();
  basis_.resize(bins);
  for (std::uint32_t j = 0; j < bins; ++j) {
    const double x = 2.0 * ((j + 0.5) / bins - 0.5);
    const double legendre[3] = {1.0, x, 0.5 * (3.0 * x * x - 1.0)};
    for (int t = 0; t < reference_.terms(); ++t) {
      basis_[j][static_cast<std::size_t>(t)] =
          static_cast<std::int32_t>(std::lround(std::ldexp(legendre[reference_.degree(t)], kBasisBits)));
    }
  }
}

Classification FixedSessionClassifier::classify(const float* query, std::size_t n) const {
  const FixedClassifier::Prepared p = eq12_.prepare(query, n);  // validated, quantised
  const CompactTable& ct = eq12_.compact();
  const ExemplarTable& table = reference_.table();
  const SessionPrior& prior = reference_.prior();
  const std::uint32_t rows = ct.n_rows();
  const std::size_t pb = ct.padded_bins();
  const int k = reference_.terms();
  const double step = ct.step_mm(), step2 = step * step;
  const bool huber = std::isfinite(prior.huber_k);
  const double hk = prior.huber_k;
  const auto has = [](const std::uint8_t* bits, std::size_t i) { return ((bits[i / 8] >> (i % 8)) & 1u) != 0; };

  std::vector<std::uint32_t> at;  // the bins compared in a row
  std::vector<std::int32_t> e;    // query - candidate, steps: |e| <= 65534
  std::vector<std::int64_t> res;  // residuals, Q16 steps
  std::vector<double> out_w;      // outliers' robust weights (0: an inlier)
  Classification out;
  out.ranking.reserve(ct.n_candidates());
  for (std::size_t c = 0; c < ct.n_candidates(); ++c) {
    const std::uint32_t index = ct.candidates()[c];
    const std::int16_t* values = ct.values(c);
    const std::uint8_t* valid = ct.validity(c);
    double total = 0.0, energy = 0.0;
    std::uint32_t compared = 0;
    for (std::uint32_t r = 0; r < rows; ++r) {
      const double sigma = prior.noise_scale * reference_.noise_mm()[index * rows + r];
      const double v_mm = sigma * sigma + prior.floor_mm * prior.floor_mm;
      const double v = v_mm / step2, sd = std::sqrt(v);  // in steps
      at.clear();
      e.clear();
      std::size_t asked = 0;
      const std::size_t lo = p.first[r] * kCompactBlock, hi = p.last[r] * kCompactBlock;
      for (std::size_t b = lo; b < hi && b < table.n_bins(); ++b) {
        const std::size_t i = static_cast<std::size_t>(r) * pb + b;
        if (!has(p.mask.data(), i)) continue;
        ++asked;
        if (valid != nullptr && !has(valid, i)) continue;
        at.push_back(static_cast<std::uint32_t>(b));
        e.push_back(std::int32_t{p.q[i]} - std::int32_t{values[i]});
      }
      const std::size_t nr = e.size();
      compared += static_cast<std::uint32_t>(nr);
      res.resize(nr);
      for (std::size_t i = 0; i < nr; ++i) res[i] = std::int64_t{e[i]} * (std::int64_t{1} << kFitBits);
      const std::int64_t threshold = huber ? clamp_round(hk * sd * kFitScale, kMaxThreshold) : kMaxThreshold;
      double penalty = 0.0, logdet = 0.0;
      if (k > 0) {
        // Per term, its prior variance and the log of their product in steps^2.
        std::array<double, kMaxTerms> pv{};
        for (int t = 0; t < k; ++t)
          pv[static_cast<std::size_t>(t)] = reference_.prior_var(r)[static_cast<std::size_t>(t)] / step2;
        const double log_det_prior = reference_.log_det_prior(r) - k * std::log(step2);
        out_w.assign(nr, 0.0);  // 0: an inlier (weight 1); else an outlier's Huber weight
        std::array<double, kMaxTerms> beta{};
        for (int it = 0; it < prior.iterations; ++it) {
          // The normal equations' sums. Inliers (weight 1) in int64: |a a| <= 2^28 and |e a| <= 2^30,
          // over 2^16 elements within 2^44 and 2^46. Outliers, rare, in double with their weight
          // T / |r| (a weight quantised to a few bits would move the fit of a far outlier).
          std::int64_t G[kMaxTerms][kMaxTerms] = {}, h[kMaxTerms] = {};
          double Go[kMaxTerms][kMaxTerms] = {}, ho[kMaxTerms] = {};
          for (std::size_t i = 0; i < nr; ++i) {
            const auto& a = basis_[at[i]];
            if (out_w[i] == 0.0) {
              for (int s = 0; s < k; ++s) {
                h[s] += std::int64_t{e[i]} * a[static_cast<std::size_t>(s)];
                for (int t = 0; t <= s; ++t) {
                  G[s][t] += std::int64_t{a[static_cast<std::size_t>(s)]} * a[static_cast<std::size_t>(t)];
                }
              }
            } else {
              for (int s = 0; s < k; ++s) {
                const double as = a[static_cast<std::size_t>(s)] * kBasisUnit;
                ho[s] += out_w[i] * e[i] * as;
                for (int t = 0; t <= s; ++t) {
                  Go[s][t] += out_w[i] * as * (a[static_cast<std::size_t>(t)] * kBasisUnit);
                }
              }
            }
          }
          std::array<std::array<double, kMaxTerms>, kMaxTerms> P{};
          std::array<double, kMaxTerms> rhs{};
          for (int s = 0; s < k; ++s) {
            rhs[static_cast<std::size_t>(s)] = (static_cast<double>(h[s]) * kBasisUnit + ho[s]) / v;
            for (int t = 0; t <= s; ++t) {
              const double g = (static_cast<double>(G[s][t]) * kBasisUnit2 + Go[s][t]) / v;
              P[static_cast<std::size_t>(s)][static_cast<std::size_t>(t)] = g;
              P[static_cast<std::size_t>(t)][static_cast<std::size_t>(s)] = g;
            }
            P[static_cast<std::size_t>(s)][static_cast<std::size_t>(s)] += 1.0 / pv[static_cast<std::size_t>(s)];
          }
          logdet = session_detail::cholesky_solve(P, k, rhs, beta) + log_det_prior;
          // The fit in Q16 steps from the coefficients in Q16 (|B a| <= 2^54): residuals within 2^43.
          std::array<std::int64_t, kMaxTerms> B{};
          for (int s = 0; s < k; ++s) {
            B[static_cast<std::size_t>(s)] =
                clamp_round(beta[static_cast<std::size_t>(s)] * kFitScale, kMaxCoefficient);
          }
          for (std::size_t i = 0; i < nr; ++i) {
            const auto& a = basis_[at[i]];
            std::int64_t fit = 0;
            for (int s = 0; s < k; ++s) fit += B[static_cast<std::size_t>(s)] * a[static_cast<std::size_t>(s)];
            const std::int64_t rounded = (fit + (std::int64_t{1} << (kBasisBits - 1))) >> kBasisBits;
            res[i] = std::int64_t{e[i]} * (std::int64_t{1} << kFitBits) - rounded;
          }
          if (!huber) break;
          // Every weight 1 before and after: the next pass would solve the same system again.
          bool changed = false;
          for (std::size_t i = 0; i < nr; ++i) {
            const std::int64_t mag = std::llabs(res[i]);
            const double was = out_w[i];
            out_w[i] = mag <= threshold ? 0.0 : static_cast<double>(threshold) / static_cast<double>(mag);
            changed = changed || out_w[i] != was;
          }
          if (!changed) break;
        }
        for (int s = 0; s < k; ++s) {
          penalty += 0.5 * beta[static_cast<std::size_t>(s)] * beta[static_cast<std::size_t>(s)] /
                     pv[static_cast<std::size_t>(s)];
        }
      }
      // The data term: inliers' squares in Q8 (saturating), outliers' magnitudes in Q16.
      std::uint64_t squares = 0;
      std::int64_t beyond = 0, n_beyond = 0;
      for (std::size_t i = 0; i < nr; ++i) {
        const std::int64_t mag = std::llabs(res[i]);
        if (huber && mag > threshold) {
          beyond += mag;  // <= 2^43 each: within 2^59
          ++n_beyond;
          continue;
        }
        const auto q8 = static_cast<std::uint64_t>((mag + 128) >> 8);  // <= 2^35
        squares = add_saturating(squares, q8 > 0xffffffffu ? std::numeric_limits<std::uint64_t>::max() : q8 * q8);
      }
      double data = static_cast<double>(squares) * (kFitUnit / 2.0) / v;
      if (huber)
        data += hk * (static_cast<double>(beyond) * kFitUnit) / sd - 0.5 * hk * hk * static_cast<double>(n_beyond);
      energy += data + penalty;
      const double log_norm = 0.5 * (kLog2Pi + std::log(v_mm));
      total += data + static_cast<double>(nr) * log_norm + penalty + 0.5 * logdet +
               static_cast<double>(asked - nr) * (0.5 + log_norm);
    }
    if (compared == 0) continue;
    out.ranking.push_back(Match{index, total, compared, chi_square_deviate(2.0 * energy, compared)});
  }
  rank(out);
  return out;
}

}  // namespace tofmat
