// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// SessionClassifier: the session-robust matcher of session_classifier.hpp in
// double precision, candidate by candidate and row by row.
#include "tofmat/core/session_classifier.hpp"

#include "session_solve.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>

namespace tofmat {

namespace {

constexpr double kLog2Pi = 1.8378770664093453;  // log(2 pi)

// numpy.median: the mean of the two middle values for an even count.
double median(std::vector<double> v) {
  const std::size_t n = v.size();
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(n / 2), v.end());
  const double hi = v[n / 2];
  if (n % 2 == 1) return hi;
  return 0.5 * (hi + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(n / 2)));
}

}  // namespace

SessionPrior SessionPrior::tuned(const ExemplarTable& table) {
  if (table.n_rows() == 0) throw std::invalid_argument("session prior: the table has no rows");
  SessionPrior p;
  if (const auto& c = table.calibration()) {  // the table's own (format 1.3)
    p.offset_sd_mm = c->offset_sd_mm;
    p.drift1_sd_mm = c->drift1_sd_mm;
    p.drift2_sd_mm = c->drift2_sd_mm;
    p.noise_scale = c->noise_scale;
    p.floor_mm = c->floor_mm;
    p.huber_k = c->huber_k;
    p.iterations = static_cast<int>(c->iterations);
    return p;
  }
  const bool kinect = table.n_rows() == 2 && table.rows()[0] == RowSpec{16, 120} && table.rows()[1] == RowSpec{80, 120};
  p.offset_sd_mm = kinect ? std::vector<double>{2.27, 0.73} : std::vector<double>(table.n_rows(), 1.0);
  return p;
}

void SessionPrior::validate(std::uint32_t n_rows) const {
  const auto bad = [](double v) { return !(v >= 0.0) || std::isinf(v); };
  if (offset_sd_mm.size() != n_rows) {
    throw std::invalid_argument("session prior: " + std::to_string(offset_sd_mm.size()) +
                                " row offsets for a table of " + std::to_string(n_rows) + " rows");
  }
  for (double s : offset_sd_mm) {
    if (bad(s)) throw std::invalid_argument("session prior: a row offset's sd must be finite and >= 0");
  }
  if (bad(drift1_sd_mm) || bad(drift2_sd_mm)) {
    throw std::invalid_argument("session prior: the drift's sd must be finite and >= 0");
  }
  if (bad(noise_scale) || bad(floor_mm)) {
    throw std::invalid_argument("session prior: noise_scale and floor_mm must be finite and >= 0");
  }
  if (noise_scale == 0.0 && floor_mm == 0.0) {
    throw std::invalid_argument("session prior: noise_scale and floor_mm are both 0 (no noise at all)");
  }
  if (!(huber_k > 0.0)) throw std::invalid_argument("session prior: huber_k must be > 0 (infinity: Gaussian)");
  if (iterations < 1) throw std::invalid_argument("session prior: iterations must be at least 1");
}

SessionPrior scaled(const SessionPrior& prior, double scale) {
  if (!(scale >= 0.0) || std::isinf(scale))
    throw std::invalid_argument("session prior: a scale must be finite and >= 0");
  SessionPrior p = prior;
  for (double& s : p.offset_sd_mm) s *= scale;
  p.drift1_sd_mm *= scale;
  p.drift2_sd_mm *= scale;
  return p;
}

std::vector<double> curve_roughness(const ExemplarTable& table) {
  const std::uint32_t rows = table.n_rows(), bins = table.n_bins();
  std::vector<double> out(table.n_materials() * rows, std::nan(""));
  for (std::size_t m = 0; m < table.n_materials(); ++m) {
    for (std::uint32_t r = 0; r < rows; ++r) {
      const float* v = table.material_values(m) + static_cast<std::size_t>(r) * bins;
      std::vector<double> x;
      for (std::uint32_t j = 0; j < bins; ++j) {
        if (!std::isnan(v[j])) x.push_back(v[j]);
      }
      if (x.size() < 5) continue;
      std::vector<double> d2(x.size() - 2);
      for (std::size_t j = 0; j + 2 < x.size(); ++j) d2[j] = x[j + 2] - 2.0 * x[j + 1] + x[j];
      const double med = median(d2);
      for (double& d : d2) d = std::fabs(d - med);
      out[m * rows + r] = 1.4826 * median(d2) / std::sqrt(6.0);
    }
  }
  return out;
}

double cube_root(double x) {
  // Why not std::cbrt: glibc's takes about 130 aarch64 instructions, and a
  // frame's label under the session learner takes one a candidate and scale
  // (6 x 29 on the real database: over 20,000 instructions of a 1 M budget).
  // Here x = f 2^(3q) with f in [1, 8) (exact, from the exponent's bits), an
  // exponent-thirds first guess of cbrt(f) (within about 3 %), three Halley
  // steps y <- y (y^3 + 2f) / (2y^3 + f), each cubing the error, and the
  // result scaled by 2^q (exact): within 4 ulp of the cube root (std::cbrt's
  // own is within 1), about 40 instructions. f's range keeps every step
  // away from overflow and underflow.
  if (!std::isnormal(x)) return std::cbrt(x);  // 0, subnormal, inf, NaN: the library's rules
  std::uint64_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  const int e = static_cast<int>((bits >> 52) & 0x7FF) - 1023;  // x's binary exponent, -1022..1023
  const int q = (e >= 0 ? e : e - 2) / 3;                       // floor(e / 3)
  const int r = e - 3 * q;                                      // 0, 1 or 2
  const std::uint64_t mantissa = bits & ((std::uint64_t{1} << 52) - 1);
  const std::uint64_t f_bits = mantissa | (static_cast<std::uint64_t>(r + 1023) << 52);
  std::uint64_t y_bits = f_bits / 3 + 0x2A9F7893782DA1CEULL;  // (the exponent's bias thirded, a mantissa offset)
  double f, y, scale;
  std::memcpy(&f, &f_bits, sizeof f);
  std::memcpy(&y, &y_bits, sizeof y);
  for (int i = 0; i < 3; ++i) {
    const double y3 = y * y * y;
    y *= (y3 + 2.0 * f) / (2.0 * y3 + f);
  }
  const std::uint64_t scale_bits = static_cast<std::uint64_t>(q + 1023) << 52;  // 2^q, q in -341..341
  std::memcpy(&scale, &scale_bits, sizeof scale);
  return std::signbit(x) ? -(y * scale) : y * scale;
}

double chi_square_deviate(double q, double n) {
  const double a = 2.0 / (9.0 * n);
  return (cube_root(std::max(q, 0.0) / n) - (1.0 - a)) / std::sqrt(a);
}

std::vector<double> candidate_vagueness(const std::vector<double>& noise_mm, std::uint32_t n_rows,
                                        const SessionPrior& prior) {
  if (n_rows == 0 || noise_mm.size() % n_rows != 0) {
    throw std::invalid_argument("candidate_vagueness: the noise is not materials x rows");
  }
  const std::size_t materials = noise_mm.size() / n_rows;
  const auto variance = [&](std::size_t m, std::uint32_t r) {
    const double s = prior.noise_scale * noise_mm[m * n_rows + r];
    return s * s + prior.floor_mm * prior.floor_mm;
  };
  std::vector<double> typical(n_rows);
  for (std::uint32_t r = 0; r < n_rows; ++r) {
    std::vector<double> v(materials);
    for (std::size_t m = 0; m < materials; ++m) v[m] = variance(m, r);
    typical[r] = materials ? median(std::move(v)) : 1.0;
  }
  std::vector<double> out(materials, 1.0);
  for (std::size_t m = 0; m < materials; ++m) {
    double ratio = 0.0;
    for (std::uint32_t r = 0; r < n_rows; ++r) ratio += variance(m, r) / typical[r];
    ratio /= n_rows;
    out[m] = std::isfinite(ratio) ? std::max(1.0, ratio) : 1.0;
  }
  return out;
}

SessionClassifier::SessionClassifier(std::shared_ptr<const ExemplarTable> table, SessionPrior prior,
                                     std::vector<double> noise_mm, std::vector<std::uint32_t> candidates)
    : table_(std::move(table)), prior_(std::move(prior)), noise_(std::move(noise_mm)) {
  if (!table_) throw std::invalid_argument("classifier needs a table");
  prior_.validate(table_->n_rows());
  candidates_ = candidate_indices(table_->n_materials(), std::move(candidates));
  const std::size_t size = table_->n_materials() * table_->n_rows();
  if (noise_.empty()) {
    // The table's measured noise where it has one, the curve's roughness elsewhere.
    noise_ = curve_roughness(*table_);
    const auto& stored = table_->noise_mm();
    for (std::size_t i = 0; i < stored.size(); ++i) {
      if (!std::isnan(stored[i])) noise_[i] = stored[i];
    }
  }
  if (noise_.size() != size) {
    throw std::invalid_argument("noise_mm has " + std::to_string(noise_.size()) + " values, the table needs " +
                                std::to_string(table_->n_materials()) + " x " + std::to_string(table_->n_rows()));
  }
  // A material without a usable noise level (too few elements) gets the
  // median of the others (0.3 mm, the database's typical roughness, if none).
  std::vector<double> usable;
  for (double s : noise_) {
    if (s > 0.0 && std::isfinite(s)) usable.push_back(s);
  }
  const double fill = usable.empty() ? 0.3 : median(usable);
  for (double& s : noise_) {
    if (!(s > 0.0 && std::isfinite(s))) s = fill;
  }
  const std::uint32_t rows = table_->n_rows();
  vagueness_ = candidate_vagueness(noise_, rows, prior_);
  const double drift[2] = {prior_.drift1_sd_mm, prior_.drift2_sd_mm};
  if (std::all_of(prior_.offset_sd_mm.begin(), prior_.offset_sd_mm.end(), [](double s) { return s > 0.0; }))
    degree_[terms_++] = 0;
  for (int d = 0; d < 2; ++d) {
    if (drift[d] > 0.0) degree_[terms_++] = d + 1;
  }
  prior_var_.resize(rows);
  log_det_prior_.assign(rows, 0.0);
  for (std::uint32_t r = 0; r < rows; ++r) {
    for (int t = 0; t < terms_; ++t) {
      const double s = degree_[t] == 0 ? prior_.offset_sd_mm[r] : drift[degree_[t] - 1];
      prior_var_[r][t] = s * s;
      log_det_prior_[r] += std::log(s * s);
    }
  }
}

Classification SessionClassifier::classify(const float* query, std::size_t n) const {
  const QueryElements q = gather_query(*table_, query, n);
  const std::uint32_t rows = table_->n_rows(), bins = table_->n_bins();
  const int k = terms_;
  // The query's elements by row, and their basis values.
  std::vector<std::size_t> row_begin(rows + 1, 0);
  for (std::uint32_t i : q.index) ++row_begin[i / bins + 1];
  for (std::uint32_t r = 0; r < rows; ++r) row_begin[r + 1] += row_begin[r];
  std::vector<std::array<double, kMaxTerms>> basis(q.index.size());
  for (std::size_t i = 0; i < q.index.size(); ++i) {
    const std::uint32_t j = q.index[i] % bins;
    for (int t = 0; t < k; ++t) basis[i][t] = session_basis(j, bins, degree_[t]);
  }
  const bool huber = std::isfinite(prior_.huber_k);
  const double hk = prior_.huber_k;

  std::vector<double> e, z, w;
  std::vector<std::size_t> at;  // which query element each e is
  Classification out;
  out.ranking.reserve(candidates_.size());
  for (std::uint32_t p : candidates_) {
    const float* ex = table_->material_values(p);
    double total = 0.0, energy = 0.0;  // energy: Q / 2 (session_classifier.hpp)
    std::uint32_t compared = 0;
    for (std::uint32_t r = 0; r < rows; ++r) {
      const double sigma = prior_.noise_scale * noise_[p * rows + r];
      const double v = sigma * sigma + prior_.floor_mm * prior_.floor_mm, sd = std::sqrt(v);
      e.clear();
      at.clear();
      for (std::size_t i = row_begin[r]; i < row_begin[r + 1]; ++i) {
        const float c = ex[q.index[i]];
        if (std::isnan(c)) continue;
        e.push_back(q.value[i] - static_cast<double>(c));
        at.push_back(i);
      }
      const std::size_t nr = e.size();
      const std::size_t lacking = (row_begin[r + 1] - row_begin[r]) - nr;
      compared += static_cast<std::uint32_t>(nr);
      z.assign(nr, 0.0);
      double penalty = 0.0, logdet = 0.0;  // log det(S P), S = diag(prior variances)
      if (k == 0) {
        for (std::size_t i = 0; i < nr; ++i) z[i] = std::fabs(e[i]) / sd;
      } else {
        w.assign(nr, 1.0);
        std::array<double, kMaxTerms> beta{};
        std::array<std::array<double, kMaxTerms>, kMaxTerms> P{};
        for (int it = 0; it < prior_.iterations; ++it) {
          // Weighted normal equations: P beta = b.
          std::array<double, kMaxTerms> b{};
          for (auto& row : P) row.fill(0.0);
          for (std::size_t i = 0; i < nr; ++i) {
            const auto& a = basis[at[i]];
            for (int s = 0; s < k; ++s) {
              b[s] += w[i] * e[i] * a[s];
              for (int t = 0; t < k; ++t) P[s][t] += w[i] * a[s] * a[t];
            }
          }
          for (int s = 0; s < k; ++s) {
            b[s] /= v;
            for (int t = 0; t < k; ++t) P[s][t] /= v;
            P[s][s] += 1.0 / prior_var_[r][s];
          }
          logdet = session_detail::cholesky_solve(P, k, b, beta) + log_det_prior_[r];
          for (std::size_t i = 0; i < nr; ++i) {
            double fit = 0.0;
            for (int s = 0; s < k; ++s) fit += beta[s] * basis[at[i]][s];
            z[i] = std::fabs(e[i] - fit) / sd;
          }
          if (!huber) break;
          // The same weights again would solve the same system again (to the bit): stop.
          bool changed = false;
          for (std::size_t i = 0; i < nr; ++i) {
            const double was = w[i];
            w[i] = std::min(1.0, hk / std::max(z[i], 1e-12));
            changed = changed || w[i] != was;
          }
          if (!changed) break;
        }
        for (int s = 0; s < k; ++s) penalty += 0.5 * beta[s] * beta[s] / prior_var_[r][s];
      }
      double data = 0.0;
      for (std::size_t i = 0; i < nr; ++i) {
        data += huber && z[i] > hk ? hk * z[i] - 0.5 * hk * hk : 0.5 * z[i] * z[i];
      }
      energy += data + penalty;
      const double log_norm = 0.5 * (kLog2Pi + std::log(v));
      total += data + static_cast<double>(nr) * log_norm + penalty + 0.5 * logdet +
               static_cast<double>(lacking) * (0.5 + log_norm);
    }
    if (compared == 0) continue;  // nothing in common: this candidate cannot be judged
    out.ranking.push_back(Match{p, total, compared, chi_square_deviate(2.0 * energy, compared)});
  }
  rank(out);
  return out;
}

}  // namespace tofmat
