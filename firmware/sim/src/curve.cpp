// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The noise-free relative-distortion curve of a material over the bins, as the real database records it.
#include "tofmat/sim/curve.hpp"

#include <cmath>
#include <stdexcept>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/depth_bins.hpp"
#include "tofmat/core/features.hpp"
#include "tofmat/sim/measurement.hpp"

namespace tofmat::sim {
namespace {

// Spec 4.1: the database averaged wrapped depths, so with per-sample noise of
// sigma_f = noise_mm * 120 / f the mean near a wrap is pulled inwards:
// E[d_f] = d_f + U_f [Q(d_f / sigma_f) - Q((U_f - d_f) / sigma_f)].
double expected_wrapped(double d_mm, double freq_mhz, double noise_mm) {
  if (!(noise_mm > 0.0)) return d_mm;
  const double u = 150000.0 / freq_mhz;  // C_DEV / (2 f), mm
  const double sigma = noise_mm * 120.0 / freq_mhz;
  const auto q = [](double x) { return 0.5 * std::erfc(x / std::sqrt(2.0)); };
  return d_mm + u * (q(d_mm / sigma) - q((u - d_mm) / sigma));
}

}  // namespace

std::vector<float> distortion_curve(const DeviceProfile& device, const Material& material, const BinSpec& bins,
                                    const std::vector<RowSpec>& rows, double incidence_rad, CurveMethod method,
                                    const SweepSpec& sweep) {
  bins.validate();
  material.validate();
  if (!(sweep.step_mm > 0.0) || !(sweep.stop_mm > sweep.start_mm) ||
      (sweep.stop_mm - sweep.start_mm) / sweep.step_mm > 1e7) {
    throw std::invalid_argument("sweep needs start < stop and at most 1e7 steps");
  }
  std::array<HarmonicWeights, 3> w;
  for (std::size_t g = 0; g < 3; ++g) w[g] = harmonic_weights(device.groups[g], material, incidence_rad);
  std::array<double, 3> freqs{};
  for (std::size_t g = 0; g < 3; ++g) freqs[g] = device.groups[g].freq_mhz;

  const auto n_rows = static_cast<std::uint32_t>(rows.size());
  const std::size_t n = static_cast<std::size_t>((sweep.stop_mm - sweep.start_mm) / sweep.step_mm) + 1;
  std::vector<double> comb(n);
  std::vector<float> vals(n * n_rows);
  for (std::size_t i = 0; i < n; ++i) {
    const double range = sweep.start_mm + sweep.step_mm * static_cast<double>(i);
    const auto d = ideal_depths(device, w, range);
    comb[i] = unwrap_depths(d).combined_mm;
    std::array<double, 3> mean{};
    for (std::size_t g = 0; g < 3; ++g) mean[g] = expected_wrapped(d[g], freqs[g], material.noise_mm);
    frequency_features(rows, freqs.data(), mean.data(), 3, &vals[i * n_rows]);
  }

  if (method == CurveMethod::kBinMean) {
    DepthBinAccumulator acc(bins, n_rows);
    for (std::size_t i = 0; i < n; ++i) acc.add(comb[i], &vals[i * n_rows]);
    return acc.query();
  }

  // Interpolate each row at the bin centres along the combined depth. The
  // combined depth grows with range (distortion slopes are far below 1), so
  // walk the sweep once; a centre outside the sweep stays NaN.
  std::vector<float> out(static_cast<std::size_t>(n_rows) * bins.count, NAN);
  std::size_t i = 0;
  for (std::uint32_t b = 0; b < bins.count; ++b) {
    const double c = bins.centre_mm(b);
    while (i + 1 < n && comb[i + 1] < c) ++i;
    if (i + 1 >= n || comb[i] > c || !(comb[i + 1] > comb[i])) continue;
    const double t = (c - comb[i]) / (comb[i + 1] - comb[i]);
    for (std::uint32_t r = 0; r < n_rows; ++r) {
      const double v0 = vals[i * n_rows + r], v1 = vals[(i + 1) * n_rows + r];
      // Across a phase wrap the rows jump by a whole wavelength: take the
      // nearer sample rather than a value between the two branches.
      const double v = std::fabs(v1 - v0) > 100.0 ? (t < 0.5 ? v0 : v1) : v0 + t * (v1 - v0);
      out[static_cast<std::size_t>(r) * bins.count + b] = static_cast<float>(v);
    }
  }
  return out;
}

}  // namespace tofmat::sim
