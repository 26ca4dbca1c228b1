// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Calibration: temperatures by sweep length, softmax probabilities over a ranking, open-set rejection.
#include "tofmat/core/confidence.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tofmat {

namespace {

using Knots = std::vector<std::pair<double, double>>;

// Linear in log length between knots, held beyond the ends.
double interpolate(const Knots& knots, double bins) {
  if (bins <= knots.front().first) return knots.front().second;
  if (bins >= knots.back().first) return knots.back().second;
  const auto hi = std::upper_bound(knots.begin(), knots.end(), bins,
                                   [](double b, const std::pair<double, double>& k) { return b < k.first; });
  const auto lo = hi - 1;
  const double u = std::log(bins / lo->first) / std::log(hi->first / lo->first);
  return lo->second + u * (hi->second - lo->second);
}

void validate_lengths(const Knots& knots, const char* what) {
  double last = 0.0;
  for (const auto& k : knots) {
    if (!(k.first > last) || !std::isfinite(k.first)) {
      throw std::invalid_argument(std::string("calibration: ") + what + ": lengths must be finite, > 0 and increasing");
    }
    last = k.first;
  }
}

}  // namespace

Calibration Calibration::tuned(const std::string& method) {
  // From `tofmat evaluate --source curves --json`, the tuning split's
  // "temperature" of each method: the Brier score's T, raised until no label
  // of a length is wrong at a confidence of 0.9 or more on the tuning split
  // (drawn 6 x larger for it) at 0, 0.25, 0.5, 1 and 2 x the calibration's
  // session spreads, the fit tempered with the candidates' vagueness
  // (tests/python/test_confidence.py fits them again and checks these); and
  // the open-set threshold docs/evaluation.md chose from the tuning split's
  // false-reject curve.
  Calibration c;
  if (method == "eq12") {
    c.temperatures = {{1, 824.68}, {3, 1726.0}, {10, 1071.8}, {30, 518.68}, {100, 363.56}};
  } else if (method == "session") {
    c.temperatures = {{1, 2.9874}, {3, 3.4878}, {10, 5.269}, {30, 9.5121}, {100, 15.916}};
    c.unknown_fits = {{1, 1.1329}, {3, 1.8806}, {10, 4.4808}, {30, 7.5325}, {100, 27.353}};
  } else {
    throw std::invalid_argument("calibration: unknown method '" + method + "': 'eq12' or 'session'");
  }
  return c;
}

Calibration Calibration::tuned(const std::string& method, const ExemplarTable& table) {
  if (table.calibration()) {
    if (const MethodCalibration* m = table.calibration()->method(method))
      return Calibration{m->temperatures, m->unknown_fits};
  }
  return tuned(method);
}

// (Beside Calibration::validate: a table's calibration holds its knots.)
void TableCalibration::validate(std::uint32_t n_rows) const {
  const auto bad = [](double v) { return !(v >= 0.0) || std::isinf(v); };
  if (offset_sd_mm.size() != n_rows) {
    throw std::invalid_argument("table calibration: " + std::to_string(offset_sd_mm.size()) +
                                " row offsets for a table of " + std::to_string(n_rows) + " rows");
  }
  for (double v : offset_sd_mm)
    if (bad(v)) throw std::invalid_argument("table calibration: a row offset's sd must be finite and >= 0");
  if (bad(drift1_sd_mm) || bad(drift2_sd_mm) || bad(noise_scale) || bad(floor_mm)) {
    throw std::invalid_argument("table calibration: drift sds, noise_scale and floor_mm must be finite and >= 0");
  }
  if (noise_scale == 0.0 && floor_mm == 0.0) {
    throw std::invalid_argument("table calibration: noise_scale and floor_mm are both 0 (no noise at all)");
  }
  if (!(huber_k > 0.0)) throw std::invalid_argument("table calibration: huber_k must be > 0");
  if (iterations < 1 || iterations > 100) throw std::invalid_argument("table calibration: iterations must be 1..100");
  for (std::size_t i = 0; i < methods.size(); ++i) {
    const MethodCalibration& m = methods[i];
    if (m.method != "eq12" && m.method != "session") {
      throw std::invalid_argument("table calibration: unknown method '" + m.method + "': 'eq12' or 'session'");
    }
    for (std::size_t j = 0; j < i; ++j)
      if (methods[j].method == m.method) throw std::invalid_argument("table calibration: '" + m.method + "' twice");
    if (m.temperatures.size() > kMaxCalibrationKnots || m.unknown_fits.size() > kMaxCalibrationKnots) {
      throw std::invalid_argument("table calibration: at most " + std::to_string(kMaxCalibrationKnots) +
                                  " knots a method");
    }
    Calibration{m.temperatures, m.unknown_fits}.validate();
  }
}

void Calibration::validate() const {
  if (temperatures.empty()) throw std::invalid_argument("calibration: give at least one (bins, temperature) knot");
  validate_lengths(temperatures, "temperatures");
  validate_lengths(unknown_fits, "unknown_fits");
  for (const auto& k : temperatures) {
    if (!(k.second > 0.0) || !std::isfinite(k.second)) {
      throw std::invalid_argument("calibration: temperatures must be finite and > 0");
    }
  }
  for (const auto& k : unknown_fits) {
    if (std::isnan(k.second)) throw std::invalid_argument("calibration: an unknown_fits threshold is NaN");
  }
}

double Calibration::temperature(double bins) const { return interpolate(temperatures, bins); }

double Calibration::unknown_fit(double bins) const {
  return unknown_fits.empty() ? std::numeric_limits<double>::infinity() : interpolate(unknown_fits, bins);
}

namespace {

// The sweep's length in bins: the best match's compared elements over the rows.
double sweep_bins(const Classification& c, std::uint32_t n_rows) {
  return static_cast<double>(c.best().valid) / std::max<std::uint32_t>(n_rows, 1);
}

}  // namespace

double fit_tempering(const Match& best, double vagueness) {
  if (best.valid == 0 || std::isnan(best.fit)) return 1.0;
  if (std::isinf(best.fit)) return best.fit > 0.0 ? 1e6 : 1.0;  // +inf: fits nothing at all
  // The inverse of chi_square_deviate: Q/n = (1 - a + z sqrt(a))^3, a = 2 / (9n).
  const double a = 2.0 / (9.0 * static_cast<double>(best.valid));
  const double c = std::max(1.0 - a + best.fit * std::sqrt(a), 0.0);
  // At the typical noise the residuals weigh `vagueness` times what they weigh at the candidate's own.
  const double k = vagueness > 1.0 ? std::min(vagueness, 1e6) : 1.0;  // (NaN: 1)
  return std::clamp(c * c * c * k, 1.0, 1e6);
}

bool rejected(const Classification& c, std::uint32_t n_rows, const Calibration& calibration) {
  return !c.ranking.empty() && c.best().fit > calibration.unknown_fit(sweep_bins(c, n_rows));  // false for NaN
}

Verdict judge(const Classification& c, std::uint32_t n_rows, const Calibration& calibration,
              const std::vector<double>& vagueness) {
  Verdict v;
  if (c.ranking.empty()) return v;
  const std::uint32_t best_index = c.best().index;
  const double vague = best_index < vagueness.size() ? vagueness[best_index] : 1.0;
  const double t = calibration.temperature(sweep_bins(c, n_rows)) * fit_tempering(c.best(), vague);
  // softmax(-d / T), shifted by the best (lowest) score so that no term overflows.
  const double best = c.best().distance;
  double sum = 0.0;
  v.probability.reserve(c.ranking.size());
  for (const Match& m : c.ranking) {
    const double e = std::exp(-(m.distance - best) / t);
    v.probability.push_back(e);
    sum += e;
  }
  for (double& p : v.probability) p /= sum;
  v.unknown = rejected(c, n_rows, calibration);
  return v;
}

std::vector<MaterialRank> rank_materials(const Classification& c, const Verdict& verdict, const ExemplarTable& table) {
  if (verdict.probability.size() != c.ranking.size())
    throw std::invalid_argument("a verdict of " + std::to_string(verdict.probability.size()) +
                                " probabilities for a ranking of " + std::to_string(c.ranking.size()));
  std::vector<MaterialRank> out;
  out.reserve(c.ranking.size());
  // where each material sits in `out` (a table of up to 255 entries: a lookup per entry, not a search)
  std::vector<std::int32_t> slot(table.distinct_materials().size(), -1);
  for (std::size_t i = 0; i < c.ranking.size(); ++i) {
    const std::uint32_t id = table.material_id(c.ranking[i].index);
    if (slot[id] < 0) {
      slot[id] = static_cast<std::int32_t>(out.size());
      out.push_back({table.material_of(c.ranking[i].index), i, verdict.probability[i]});
    } else {
      out[static_cast<std::size_t>(slot[id])].probability += verdict.probability[i];
    }
  }
  return out;
}

}  // namespace tofmat
