// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// DeviceProfile: the ideal Kinect v2's parameters, their validation, and a profile for one session's state.
#include "tofmat/sim/device.hpp"

#include <cmath>
#include <stdexcept>

namespace tofmat::sim {

double saturate_tap(double t, double full_well, double sharpness) {
  if (!(full_well < std::numeric_limits<double>::infinity())) return t;
  const double u = std::fabs(t) / full_well;
  return t / std::pow(1.0 + std::pow(u, sharpness), 1.0 / sharpness);
}

DeviceProfile DeviceProfile::ideal_kinect2() {
  DeviceProfile d;
  d.name = "ideal_kinect2";
  const double freqs[3] = {80.0, 16.0, 120.0};
  for (std::size_t g = 0; g < 3; ++g) {
    d.groups[g].freq_mhz = freqs[g];
    d.groups[g].harmonic_amplitude.fill(0.0);
    d.groups[g].harmonic_phase_rad.fill(0.0);
    d.groups[g].harmonic_amplitude[1] = 1.0;
    d.groups[g].signal_scale = kDefaultSignalScale[g];
  }
  return d;
}

void DeviceProfile::validate() const {
  auto bad = [&](const std::string& what) { throw std::invalid_argument("device '" + name + "': " + what); };
  for (std::size_t g = 0; g < 3; ++g) {
    const auto& f = groups[g];
    const std::string tag = "group " + std::to_string(g) + ": ";
    if (!(f.freq_mhz > 0.0 && f.freq_mhz < 1e4)) bad(tag + "freq_mhz must be in (0, 10000)");
    if (!(std::fabs(f.scale_error) < 0.5)) bad(tag + "scale_error must be in (-0.5, 0.5)");
    if (!std::isfinite(f.phase_offset_rad)) bad(tag + "phase_offset_rad must be finite");
    if (!std::isfinite(f.decode_offset_rad)) bad(tag + "decode_offset_rad must be finite");
    if (!(f.signal_scale > 0.0 && f.signal_scale <= 10.0)) bad(tag + "signal_scale must be in (0, 10]");
    if (!(f.full_well > 0.0)) bad(tag + "full_well must be > 0 (or null: no saturation)");
    if (f.harmonic_amplitude[1] != 1.0 || f.harmonic_phase_rad[1] != 0.0) {
      bad(tag + "the fundamental's coefficient must be 1");
    }
    for (int h = 2; h <= kMaxHarmonic; ++h) {
      const auto k = static_cast<std::size_t>(h);
      if (!(f.harmonic_amplitude[k] >= 0.0 && f.harmonic_amplitude[k] <= 1.0))
        bad(tag + "harmonic amplitudes must be in [0, 1]");
      if (!std::isfinite(f.harmonic_phase_rad[k])) bad(tag + "harmonic phases must be finite");
    }
    for (int h = 0; h <= kMaxHarmonic; ++h) {
      const auto k = static_cast<std::size_t>(h);
      if (h < 2 && f.drift_amplitude[k] != 0.0) bad(tag + "session drift starts at h = 2");
      if (!(f.drift_amplitude[k] >= 0.0 && f.drift_amplitude[k] <= 1.0))
        bad(tag + "session drift amplitudes must be in [0, 1]");
      if (!std::isfinite(f.drift_phase_rad[k])) bad(tag + "session drift phases must be finite");
    }
    for (int j = 0; j < 3; ++j) {
      if (!(f.step_gain[static_cast<std::size_t>(j)] > 0.5 && f.step_gain[static_cast<std::size_t>(j)] < 2.0))
        bad(tag + "step gains must be in (0.5, 2)");
      if (!(std::fabs(f.step_offset[static_cast<std::size_t>(j)]) < 1.0)) bad(tag + "step offsets must be in (-1, 1)");
    }
  }
  if (!(range_ref_mm > 0.0 && range_ref_mm <= 1e5)) bad("range_ref_mm must be in (0, 100000]");
  if (!(saturation_sharpness >= 1.0 && saturation_sharpness <= 100.0)) bad("saturation.sharpness must be in [1, 100]");
  if (!(noise.read_noise >= 0.0 && noise.shot_gain >= 0.0 && noise.ambient >= 0.0)) bad("noise terms must be >= 0");
  if (!(signal.counts_at_1m > 0.0) || !(signal.saturation > 0.0 && signal.saturation <= 16320.0)) {
    bad("signal needs counts_at_1m > 0 and 0 < saturation <= 16320");
  }
  if (camera.width < 1 || camera.height < 1 || camera.width > 4096 || camera.height > 4096 || !(camera.fx > 0) ||
      !(camera.fy > 0)) {
    bad("camera needs 1..4096 pixels a side and positive focal lengths");
  }
}

DeviceProfile DeviceProfile::in_session(const std::array<double, 3>& state) const {
  for (double t : state) {
    if (!std::isfinite(t)) throw std::invalid_argument("device '" + name + "': a session state must be finite");
  }
  DeviceProfile out = *this;
  for (std::size_t g = 0; g < 3; ++g) {
    auto& f = out.groups[g];
    for (int h = 2; h <= kMaxHarmonic; ++h) {
      const auto k = static_cast<std::size_t>(h);
      const std::complex<double> moved = f.harmonic(h) + state[g] * f.drift(h);
      f.harmonic_amplitude[k] = std::abs(moved);
      f.harmonic_phase_rad[k] = f.harmonic_amplitude[k] > 0.0 ? std::arg(moved) : 0.0;
    }
    f.drift_amplitude.fill(0.0);
    f.drift_phase_rad.fill(0.0);
  }
  out.validate();
  return out;
}

}  // namespace tofmat::sim
