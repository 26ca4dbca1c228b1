// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The paper's features: unambiguous range, depth from phase (Eq. (1)) and the per-row relative distortions (Eq. (10)).
#include "tofmat/core/features.hpp"

#include <cmath>
#include <stdexcept>

namespace tofmat {

namespace {
constexpr double kTwoPi = 6.283185307179586476925286766559;
}

double unambiguous_range_mm(double freq_mhz) {
  // c [mm/ns] / (2 f [1/ns]); f in MHz is f/1000 per ns.
  return kSpeedOfLightMmPerNs / (2.0 * freq_mhz * 1e-3);
}

double depth_from_phase_mm(double phase_rad, double freq_mhz) {
  if (!std::isfinite(phase_rad) || !(freq_mhz > 0.0)) return NAN;
  double p = std::fmod(phase_rad, kTwoPi);
  if (p < 0.0) p += kTwoPi;
  if (p >= kTwoPi) p = 0.0;  // fmod of a value just below a multiple can round up
  return unambiguous_range_mm(freq_mhz) * (p / kTwoPi);
}

void frequency_features(const std::vector<RowSpec>& rows, const double* freqs_mhz, const double* depths_mm,
                        std::size_t n_freqs, float* out) {
  auto depth_at = [&](std::uint16_t f) -> double {
    for (std::size_t i = 0; i < n_freqs; ++i) {
      if (std::fabs(freqs_mhz[i] - f) < 0.5) return depths_mm[i];
    }
    return NAN;
  };
  for (std::size_t r = 0; r < rows.size(); ++r) {
    if (rows[r].freq_mhz == 0 || rows[r].ref_freq_mhz == 0) {
      throw std::invalid_argument("row " + std::to_string(r) + " has no frequency description");
    }
    // Eq. (10), sign flipped to the database's convention.
    out[r] = static_cast<float>(-relative_distortion_mm(depth_at(rows[r].ref_freq_mhz), depth_at(rows[r].freq_mhz)));
  }
}

}  // namespace tofmat
