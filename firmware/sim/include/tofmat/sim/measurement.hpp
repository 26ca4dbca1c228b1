// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Raw samples of one pixel and one frequency from the model, and the
// noise-free decode of a material at a range (docs/simulator-model.md, 3).
#pragma once

#include <array>
#include <complex>

#include "tofmat/sim/device.hpp"
#include "tofmat/sim/material.hpp"

namespace tofmat::sim {

// Everything in a raw sample that depends on neither range nor pixel:
// h[k] = conj(R(k f_true, alpha)) * G_k * exp(-i k delta_f) for k = 1..kMaxHarmonic
// (index 0 unused), and dc = R(0, alpha), the received DC per unit signal
// (the albedo, except for a slab, which loses light through its back).
struct HarmonicWeights {
  std::array<std::complex<double>, kMaxHarmonic + 1> h{};
  double dc = 0.0;
};
HarmonicWeights harmonic_weights(const FrequencyModel& f, const Material& m, double incidence_rad);

// The AC part of the three steps per unit signal, before the taps:
// Re{sum_h w_h exp(i h (phase + phi_j))}.
std::array<double, 3> ac_per_unit(const HarmonicWeights& w, double phase_rad);

// Taps to samples (spec 3.1): T+-_j = (DC +- AC_j) / 2,
// m_j = g_j [N(T+_j) - N(T-_j)] + o_j DC, with ac and dc already scaled by the
// signal A r_f (counts) and the full well in the same counts.
std::array<double, 3> samples_from_taps(const FrequencyModel& f, const std::array<double, 3>& ac, double dc,
                                        double full_well, double sharpness);

// The three noise-free raw samples m_j of a pixel at range_mm with pixel phase
// delta_p and signal A (counts at this pixel, before the group's signal_scale).
// `well_unit` is the count value of full_well = 1 (counts_at_1m * (1000 /
// range_ref_mm)^2 in the renderer, 1 for curves).
std::array<double, 3> raw_samples(const FrequencyModel& f, const HarmonicWeights& w, double range_mm,
                                  double pixel_phase_rad, double signal, double well_unit, double sharpness);

// Noise-free per-frequency wrapped depths (group order) of a material at
// range_mm, with the curves' fall-off A = (range_ref_mm / range)^2, through the
// camera's decode (P0-corrected, decode offsets applied).
std::array<double, 3> ideal_depths(const DeviceProfile& d, const std::array<HarmonicWeights, 3>& w, double range_mm);

}  // namespace tofmat::sim
