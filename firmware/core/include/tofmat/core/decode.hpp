// Float reference decode of the Kinect v2's three-phase measurements into
// per-frequency phase and depth (Eq. (1)), and the combined unwrapped depth.
// (The per-frame image decode with P0 tables, flags and ROI builds on these.)
#pragma once

#include <array>
#include <complex>

namespace tofmat {

inline constexpr double kPi = 3.14159265358979323846;
// Phase steps of the three sub-images of one frequency: 0, 120, 240 degrees.
inline constexpr double kPhaseStepsRad[3] = {0.0, 2.0 * kPi / 3.0, 4.0 * kPi / 3.0};
// Group order of the raw sub-images (0-2, 3-5, 6-8).
inline constexpr std::array<double, 3> kGroupFrequenciesMhz = {80.0, 16.0, 120.0};
inline constexpr int kGroup80 = 0, kGroup16 = 1, kGroup120 = 2;

// a + i b = sum_j m_j exp(-i (p0 + phi_j)): the camera's stage-1 phasor, with
// p0 the per-pixel phase correction from the P0 tables (radians).
std::complex<double> phasor_from_samples(const double m[3], double p0_rad);

// atan2 wrapped into [0, 2 pi); a zero phasor gives 0.
double phase_of(std::complex<double> z);

// Per-frequency depths (wrapped, group order 80, 16, 120 MHz) to unwrapped
// depths and their combination.
//
// Unwrapping is hierarchical from the longest wavelength: D16 = d16 (9375 mm
// unambiguous), D80 = d80 + k * 1875 with k nearest to D16, D120 = d120 + k' *
// 1250 with k' nearest to D80. The combined depth is the frequency-weighted
// mean (80 D80 + 16 D16 + 120 D120) / 216, which is what the Kinect's combined
// phase amounts to (2083.333 mm = c / (2 * 72 MHz)). Unambiguous range: 9375
// mm (the 16 MHz wavelength; 18750 mm would need the 8 MHz beat). It fails,
// picking the wrong multiple, when D16 is off by more than 937 mm or D80 by
// more than 625 mm: far beyond any noise or material distortion seen (< 200 mm).
struct UnwrappedDepth {
  std::array<double, 3> depth_mm;  // group order
  double combined_mm;
};
UnwrappedDepth unwrap_depths(const std::array<double, 3>& wrapped_mm);

}  // namespace tofmat
