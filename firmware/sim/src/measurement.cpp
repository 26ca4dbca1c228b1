#include "tofmat/sim/measurement.hpp"

#include <cmath>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/features.hpp"

namespace tofmat::sim {
namespace {
constexpr double kTwoPi = 6.283185307179586476925286766559;
constexpr double kCTrueMmPerNs = 299.792458;
}  // namespace

HarmonicWeights harmonic_weights(const FrequencyModel& f, const Material& m, double incidence_rad) {
  HarmonicWeights w{};
  const double nu = f.true_freq_hz();
  for (int h = 1; h <= kMaxHarmonic; ++h) {
    const auto g = f.harmonic(h);
    if (g == 0.0) continue;
    w[static_cast<std::size_t>(h)] =
        g * std::conj(material_response(m, h * nu, incidence_rad)) * std::polar(1.0, -h * f.phase_offset_rad);
  }
  return w;
}

std::array<double, 3> raw_samples(const FrequencyModel& f, const HarmonicWeights& w, double range_mm,
                                  double pixel_phase_rad, double signal) {
  const double t_ns = 2.0 * range_mm / kCTrueMmPerNs;
  const double x = kTwoPi * f.true_freq_hz() * 1e-9 * t_ns - pixel_phase_rad;
  std::array<double, 3> m{};
  for (int j = 0; j < 3; ++j) {
    double s = 0.0;
    for (int h = 1; h <= kMaxHarmonic; ++h) {
      const auto wh = w[static_cast<std::size_t>(h)];
      if (wh == 0.0) continue;
      s += (wh * std::polar(1.0, h * (x + kPhaseStepsRad[j]))).real();
    }
    m[static_cast<std::size_t>(j)] = signal * (f.step_gain[static_cast<std::size_t>(j)] * s + f.step_offset[static_cast<std::size_t>(j)]);
  }
  return m;
}

std::array<double, 3> ideal_depths(const DeviceProfile& d, const std::array<HarmonicWeights, 3>& w, double range_mm) {
  std::array<double, 3> out{};
  for (std::size_t g = 0; g < 3; ++g) {
    const auto m = raw_samples(d.groups[g], w[g], range_mm, 0.0, 1.0);
    const double phase = phase_of(phasor_from_samples(m.data(), 0.0));
    out[g] = depth_from_phase_mm(phase, d.groups[g].freq_mhz);
  }
  return out;
}

}  // namespace tofmat::sim
