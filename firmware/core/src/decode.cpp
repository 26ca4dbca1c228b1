// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The float reference decode of one pixel: phasor and phase from three samples, and the unwrapping of the three depths.
#include "tofmat/core/decode.hpp"

#include <cmath>

#include "tofmat/core/features.hpp"

namespace tofmat {

std::complex<double> phasor_from_samples(const double m[3], double p0_rad) {
  std::complex<double> z{0.0, 0.0};
  for (int j = 0; j < 3; ++j) z += m[j] * std::polar(1.0, -(p0_rad + kPhaseStepsRad[j]));
  return z;
}

double phase_of(std::complex<double> z) {
  if (z.real() == 0.0 && z.imag() == 0.0) return 0.0;  // also -0.0: atan2 would say pi
  double p = std::atan2(z.imag(), z.real());
  if (p < 0.0) p += 2.0 * kPi;
  if (p >= 2.0 * kPi) p = 0.0;
  return p;
}

UnwrappedDepth unwrap_depths(const std::array<double, 3>& d) {
  const double r80 = unambiguous_range_mm(kGroupFrequenciesMhz[kGroup80]);
  const double r120 = unambiguous_range_mm(kGroupFrequenciesMhz[kGroup120]);
  UnwrappedDepth u{};
  u.depth_mm[kGroup16] = d[kGroup16];
  u.depth_mm[kGroup80] = d[kGroup80] + r80 * std::nearbyint((u.depth_mm[kGroup16] - d[kGroup80]) / r80);
  u.depth_mm[kGroup120] = d[kGroup120] + r120 * std::nearbyint((u.depth_mm[kGroup80] - d[kGroup120]) / r120);
  double num = 0.0, den = 0.0;
  for (int g = 0; g < 3; ++g) {
    num += kGroupFrequenciesMhz[g] * u.depth_mm[g];
    den += kGroupFrequenciesMhz[g];
  }
  u.combined_mm = num / den;
  return u;
}

bool unwrap_consistent(const UnwrappedDepth& u, double max_gap_16_80_mm, double max_gap_80_120_mm) {
  const double gap_16_80 = std::fabs(u.depth_mm[kGroup80] - u.depth_mm[kGroup16]);
  const double gap_80_120 = std::fabs(u.depth_mm[kGroup120] - u.depth_mm[kGroup80]);
  return gap_16_80 <= max_gap_16_80_mm && gap_80_120 <= max_gap_80_120_mm;
}

}  // namespace tofmat
