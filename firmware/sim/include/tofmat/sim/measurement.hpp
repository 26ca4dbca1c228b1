// Raw samples of one pixel and one frequency from the model, and the
// noise-free decode of a material at a range (docs/simulator-model.md, 3).
#pragma once

#include <array>
#include <complex>

#include "tofmat/sim/device.hpp"
#include "tofmat/sim/material.hpp"

namespace tofmat::sim {

// conj(R(h f_true, alpha)) * G_h * exp(-i h delta_f), h = 1..7: everything in a
// raw sample that does not depend on range or pixel. Index 0 unused.
using HarmonicWeights = std::array<std::complex<double>, kMaxHarmonic + 1>;
HarmonicWeights harmonic_weights(const FrequencyModel& f, const Material& m, double incidence_rad);

// The three noise-free raw samples m_j of a pixel at range_mm with pixel phase
// delta_p and signal scale A (counts).
std::array<double, 3> raw_samples(const FrequencyModel& f, const HarmonicWeights& w, double range_mm,
                                  double pixel_phase_rad, double signal);

// Noise-free per-frequency wrapped depths (group order) of a material at
// range_mm and incidence, through the camera's decode (P0-corrected).
std::array<double, 3> ideal_depths(const DeviceProfile& d, const std::array<HarmonicWeights, 3>& w, double range_mm);

}  // namespace tofmat::sim
