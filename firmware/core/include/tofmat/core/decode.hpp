// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
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
// mm (the 16 MHz wavelength; 18750 mm would need the 8 MHz beat).
//
// It picks a wrong multiple when D16 is off by more than 937.5 mm or D80 by
// more than 625 mm. That is NOT beyond noise at low signal: with 3 counts of
// read noise per sample the phase noise of a group of amplitude A is about
// 2.46 / A rad, i.e. 367 mm of D16 at A = 10 (the mean amplitude the dark
// rule lets through), and pixels whose true signal is below the thresholds
// pass them only when the noise is large. Measured without any check (A equal
// in all groups, 1000 mm): 42 % of the pixels passing "amplitude >= 3" at
// A = 3 were more than 300 mm off, 1.9 % at A = 10. So the unwrapped depths
// must be checked (unwrap_consistent) and the decode flags failures
// (frame_decode.hpp, kDecodeUnwrap). unwrap_depths itself never fails.
struct UnwrappedDepth {
  std::array<double, 3> depth_mm;  // group order
  double combined_mm;
};
UnwrappedDepth unwrap_depths(const std::array<double, 3>& wrapped_mm);

// The consistency of an unwrapping: |D80 - D16| <= max_gap_16_80_mm and
// |D120 - D80| <= max_gap_80_120_mm (false also for NaN). Comparisons of
// depths in mm only, so that a fixed-point decode can do the same with
// integer millimetres (or any fixed scale of them): two subtractions, two
// absolute values, two compares.
//
// Why these gaps catch wrong multiples: a D80 off by one 80 MHz multiple
// (1875 mm = 1.5 x 1250 mm) leaves D120 625 mm from D80 whichever 120 MHz
// multiple is picked, so a limit of 300 mm on |D120 - D80| leaves 325 mm for
// noise and distortion before such a pixel passes. A D120 off by one 120 MHz
// multiple is at least 1250 - 625 mm from D80. What the 80/120 pair cannot
// see are errors of 3750 mm (2 x 1875 = 3 x 1250) and, through the 16 MHz
// wrap, 7500 mm (= -1875 mod 9375): those only D16 reveals, the true depth and
// the wrong one being 1875 mm (72 degrees of 16 MHz phase) apart in D16; a
// limit of 400 mm on |D80 - D16| leaves 1475 mm (0.99 rad) of 16 MHz phase
// noise before a wrong pixel passes. See DecodeOptions for the defaults.
bool unwrap_consistent(const UnwrappedDepth& u, double max_gap_16_80_mm, double max_gap_80_120_mm);

}  // namespace tofmat
