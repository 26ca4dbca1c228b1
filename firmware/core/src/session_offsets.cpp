// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// SessionOffsets: the session's terms learned from labelled sweeps
// (session_offsets.hpp).
#include "tofmat/core/session_offsets.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "session_solve.hpp"

namespace tofmat {

SessionOffsets::SessionOffsets(std::shared_ptr<const SessionClassifier> reference, double forget)
    : reference_(std::move(reference)), forget_(forget) {
  if (!reference_) throw std::invalid_argument("session offsets: no session matcher");
  if (!(forget_ > 0.0 && forget_ <= 1.0)) throw std::invalid_argument("session offsets: forget must be in (0, 1]");
  rows_ = reference_->table().n_rows();
  bins_ = reference_->table().n_bins();
  k_ = reference_->terms();
  basis_.resize(bins_);
  for (std::uint32_t j = 0; j < bins_; ++j)
    for (int t = 0; t < k_; ++t) basis_[j][t] = session_basis(j, bins_, reference_->degree(t));
  reset();
}

void SessionOffsets::reset() {
  mean_.assign(rows_, {});
  learned_.lambda.assign(rows_, {});
  learned_.eta.assign(rows_, {});
  shift_.assign(std::size_t{rows_} * bins_, 0.0F);
}

SessionOffsets::Evidence SessionOffsets::evidence(const float* query, std::size_t n,
                                                  const std::vector<std::pair<std::uint32_t, double>>& shares) const {
  const ExemplarTable& table = reference_->table();
  if (n != table.elements_per_material()) {
    throw std::invalid_argument("session offsets: a query of " + std::to_string(n) + " elements, the table's have " +
                                std::to_string(table.elements_per_material()));
  }
  double total = 0.0;
  for (const auto& [index, share] : shares) {
    if (index >= table.n_materials())
      throw std::invalid_argument("session offsets: candidate " + std::to_string(index) + " is not in the table");
    if (share >= kNegligibleShare) total += share;
  }
  Evidence out;
  if (k_ == 0 || !(total > 0.0)) return out;
  out.lambda.assign(rows_, {});
  out.eta.assign(rows_, {});
  const SessionPrior& prior = reference_->prior();
  const bool huber = std::isfinite(prior.huber_k);
  using Matrix = std::array<std::array<double, kSessionMaxTerms>, kSessionMaxTerms>;
  std::vector<std::array<double, kSessionMaxTerms>> basis;
  std::vector<double> e, w;
  for (const auto& [index, share] : shares) {
    if (share < kNegligibleShare) continue;
    const double p = share / total;
    const float* curve = table.material_values(index);
    for (std::uint32_t r = 0; r < rows_; ++r) {
      const double sigma = prior.noise_scale * reference_->noise_mm()[index * rows_ + r];
      const double v = sigma * sigma + prior.floor_mm * prior.floor_mm, sd = std::sqrt(v);
      // The row's differences from the curve beyond the learned mean.
      basis.clear();
      e.clear();
      for (std::uint32_t j = 0; j < bins_; ++j) {
        const std::size_t at = std::size_t{r} * bins_ + j;
        const float q = query[at], c = curve[at];
        if (!std::isfinite(q) || std::isnan(c)) continue;
        const auto& a = basis_[j];
        double fit = 0.0;
        for (int t = 0; t < k_; ++t) fit += a[t] * mean_[r][t];
        basis.push_back(a);
        e.push_back(static_cast<double>(q) - static_cast<double>(c) - fit);
      }
      // The session matcher's robust fit of this sweep (its prior about the learned mean):
      // its Huber weights say which elements the terms may be learned from.
      // (started from the row's median difference: one wild element must not lead the first fit)
      w.assign(e.size(), 1.0);
      if (huber && !e.empty()) {
        std::vector<double> sorted = e;
        const auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
        std::nth_element(sorted.begin(), mid, sorted.end());
        for (std::size_t i = 0; i < e.size(); ++i)
          w[i] = std::min(1.0, prior.huber_k / std::max(std::fabs(e[i] - *mid) / sd, 1e-12));
      }
      for (int it = 0; huber && it < prior.iterations; ++it) {
        Matrix P{};
        std::array<double, kSessionMaxTerms> b{}, beta{};
        for (std::size_t i = 0; i < e.size(); ++i) {
          for (int s = 0; s < k_; ++s) {
            b[s] += w[i] * e[i] * basis[i][s] / v;
            for (int t = 0; t < k_; ++t) P[s][t] += w[i] * basis[i][s] * basis[i][t] / v;
          }
        }
        for (int s = 0; s < k_; ++s) P[s][s] += 1.0 / reference_->prior_var(r)[s];
        session_detail::cholesky_solve(P, k_, b, beta);
        for (std::size_t i = 0; i < e.size(); ++i) {
          double fit = 0.0;
          for (int t = 0; t < k_; ++t) fit += beta[t] * basis[i][t];
          w[i] = std::min(1.0, prior.huber_k / std::max(std::fabs(e[i] - fit) / sd, 1e-12));
        }
      }
      // (in the information form about 0: the mean's own share added back)
      for (std::size_t i = 0; i < e.size(); ++i) {
        double fit = 0.0;
        for (int t = 0; t < k_; ++t) fit += basis[i][t] * mean_[r][t];
        for (int s = 0; s < k_; ++s) {
          out.eta[r][s] += p * w[i] * basis[i][s] * (e[i] + fit) / v;
          for (int t = 0; t < k_; ++t) out.lambda[r][s][t] += p * w[i] * basis[i][s] * basis[i][t] / v;
        }
      }
    }
  }
  return out;
}

void SessionOffsets::learn(const Evidence& sweep) {
  if (sweep.empty()) return;
  if (sweep.lambda.size() != rows_ || sweep.eta.size() != rows_)
    throw std::invalid_argument("session offsets: evidence of another count of rows");
  for (std::uint32_t r = 0; r < rows_; ++r) {
    auto& lambda = learned_.lambda[r];
    auto& eta = learned_.eta[r];
    std::array<std::array<double, kSessionMaxTerms>, kSessionMaxTerms> P{};
    for (int s = 0; s < k_; ++s) {
      eta[s] = forget_ * eta[s] + sweep.eta[r][s];
      for (int t = 0; t < k_; ++t) {
        lambda[s][t] = forget_ * lambda[s][t] + sweep.lambda[r][s][t];
        P[s][t] = lambda[s][t];
      }
      P[s][s] += 1.0 / reference_->prior_var(r)[s];  // (> 0: the prior's terms only)
    }
    session_detail::cholesky_solve(P, k_, eta, mean_[r]);
    for (std::uint32_t j = 0; j < bins_; ++j) {
      double fit = 0.0;
      for (int t = 0; t < k_; ++t) fit += basis_[j][t] * mean_[r][t];
      shift_[std::size_t{r} * bins_ + j] = static_cast<float>(fit);
    }
  }
}

std::vector<std::array<double, kSessionMaxTerms>> SessionOffsets::terms_mm() const {
  std::vector<std::array<double, kSessionMaxTerms>> out(rows_);
  for (std::uint32_t r = 0; r < rows_; ++r)
    for (int t = 0; t < k_; ++t) out[r][reference_->degree(t)] = mean_[r][t];
  return out;
}

}  // namespace tofmat
