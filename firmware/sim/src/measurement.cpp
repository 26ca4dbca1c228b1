// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Harmonic weights of a material, the AC samples per unit amplitude, and the noise-free depths at a range.
#include "tofmat/sim/measurement.hpp"

#include <cmath>
#include <stdexcept>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/features.hpp"

namespace tofmat::sim {
namespace {
constexpr double kTwoPi = 6.283185307179586476925286766559;
constexpr double kCTrueMmPerNs = 299.792458;
}  // namespace

HarmonicWeights harmonic_weights(const FrequencyModel& f, const Material& m, double incidence_rad) {
  HarmonicWeights w;
  // The received DC: albedo for kernels with K(0) = 1, less for a slab that
  // loses light through its back.
  w.dc = material_response(m, 0.0, incidence_rad).real();
  const double nu = f.true_freq_hz();
  for (int h = 1; h <= kMaxHarmonic; ++h) {
    const auto g = f.harmonic(h);
    if (g == 0.0) continue;
    w.h[static_cast<std::size_t>(h)] =
        g * std::conj(material_response(m, h * nu, incidence_rad)) * std::polar(1.0, -h * f.phase_offset_rad);
  }
  return w;
}

std::array<double, 3> ac_per_unit(const HarmonicWeights& w, double phase_rad) {
  std::array<double, 3> out{};
  for (std::size_t j = 0; j < 3; ++j) {
    // e^{i h x} by repeated multiplication: one polar per step, not per harmonic.
    const std::complex<double> e1 = std::polar(1.0, phase_rad + kPhaseStepsRad[j]);
    std::complex<double> e = 1.0;
    double s = 0.0;
    for (int h = 1; h <= kMaxHarmonic; ++h) {
      e *= e1;
      const auto wh = w.h[static_cast<std::size_t>(h)];
      if (wh != 0.0) s += (wh * e).real();
    }
    out[j] = s;
  }
  return out;
}

std::array<double, 3> samples_from_taps(const FrequencyModel& f, const std::array<double, 3>& ac, double dc,
                                        double full_well, double sharpness) {
  std::array<double, 3> m{};
  for (std::size_t j = 0; j < 3; ++j) {
    const double diff =
        saturate_tap(0.5 * (dc + ac[j]), full_well, sharpness) - saturate_tap(0.5 * (dc - ac[j]), full_well, sharpness);
    m[j] = f.step_gain[j] * diff + f.step_offset[j] * dc;
  }
  return m;
}

std::array<double, 3> raw_samples(const FrequencyModel& f, const HarmonicWeights& w, double range_mm,
                                  double pixel_phase_rad, double signal, double well_unit, double sharpness) {
  const double t_ns = 2.0 * range_mm / kCTrueMmPerNs;
  const double x = kTwoPi * f.true_freq_hz() * 1e-9 * t_ns - pixel_phase_rad;
  auto ac = ac_per_unit(w, x);
  const double a = signal * f.signal_scale;
  for (double& v : ac) v *= a;
  return samples_from_taps(f, ac, a * w.dc, f.full_well * well_unit, sharpness);
}

std::array<double, 3> ideal_depths(const DeviceProfile& d, const std::array<HarmonicWeights, 3>& w, double range_mm) {
  std::array<double, 3> out{};
  // The fall-off only matters where taps saturate (the phase is scale free).
  bool wells = false;
  for (const auto& g : d.groups) wells = wells || std::isfinite(g.full_well);
  if (wells && !(range_mm > 0.0)) throw std::invalid_argument("a device with a full well needs range > 0");
  const double a = wells ? (d.range_ref_mm / range_mm) * (d.range_ref_mm / range_mm) : 1.0;
  for (std::size_t g = 0; g < 3; ++g) {
    const auto m = raw_samples(d.groups[g], w[g], range_mm, 0.0, a, 1.0, d.saturation_sharpness);
    // theta_j = p0 - eps_f + phi_j: the decode adds eps_f to the phase.
    const double phase = phase_of(phasor_from_samples(m.data(), -d.groups[g].decode_offset_rad));
    out[g] = depth_from_phase_mm(phase, d.groups[g].freq_mhz);
  }
  return out;
}

}  // namespace tofmat::sim
