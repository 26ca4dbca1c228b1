// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A ToF camera's parameters (docs/simulator-model.md, section 2), loaded from
// a versioned device profile (data/devices/*.json).
#pragma once

#include <array>
#include <complex>
#include <cstdint>
#include <limits>
#include <string>

namespace tofmat::sim {

// Highest harmonic a profile may list. The 3-step decode folds h = 3k +- 1
// into its error terms; a correlation waveform with sharp features (the
// calibrated 16 MHz group's) needs up to h = 25.
inline constexpr int kMaxHarmonic = 32;

// The raw signal of the groups (80, 16, 120 MHz) relative to each other when a
// profile does not say: the reciprocals of libfreenect2's ab_multiplier_per_frq
// (1.322581, 1.0, 1.612903), the factors that equalise the groups' amplitudes.
inline constexpr std::array<double, 3> kDefaultSignalScale{1.0 / 1.322581, 1.0, 1.0 / 1.612903};

// One modulation frequency's illumination/demodulation and phase-step errors.
struct FrequencyModel {
  double freq_mhz = 0.0;          // nominal (what the decode assumes)
  double scale_error = 0.0;       // true frequency = nominal * (1 + scale_error)
  double phase_offset_rad = 0.0;  // delay of the reference
  double signal_scale = 1.0;      // r_f: this group's raw signal relative to the others
  // W_f: a tap's soft full well in units of counts_at_1m * (1000 / range_ref_mm)^2
  // (the 16 MHz tap signal of an albedo-1 target at range_ref_mm); +inf: none.
  double full_well = std::numeric_limits<double>::infinity();
  // eps_f: residual of the camera's P0 calibration; the decode adds it to the
  // phase (the simulated device reports P0 tables of -(delta_p + eps_f)).
  double decode_offset_rad = 0.0;
  // G_h = a_h exp(i psi_h) for h = 0..kMaxHarmonic (index 0 unused, G_1 = 1): harmonics of
  // the correlation waveform, kept as amplitude and phase (the profile's form,
  // so a profile saves and loads exactly).
  std::array<double, kMaxHarmonic + 1> harmonic_amplitude{0.0, 1.0};
  std::array<double, kMaxHarmonic + 1> harmonic_phase_rad{};
  std::complex<double> harmonic(int h) const {
    return std::polar(harmonic_amplitude[static_cast<std::size_t>(h)], harmonic_phase_rad[static_cast<std::size_t>(h)]);
  }
  // dG_h: the direction in which this group's waveform moves from one capture session to the
  // next (docs/simulator-model.md 2.2; a session in state t has G_h + t dG_h). All zero: none.
  std::array<double, kMaxHarmonic + 1> drift_amplitude{};
  std::array<double, kMaxHarmonic + 1> drift_phase_rad{};
  std::complex<double> drift(int h) const {
    return std::polar(drift_amplitude[static_cast<std::size_t>(h)], drift_phase_rad[static_cast<std::size_t>(h)]);
  }
  std::array<double, 3> step_gain{1.0, 1.0, 1.0};
  std::array<double, 3> step_offset{0.0, 0.0, 0.0};  // relative to the received DC, A r_f R(0)

  double true_freq_hz() const { return freq_mhz * 1e6 * (1.0 + scale_error); }
};

// The per-pixel phase pattern the P0 tables correct: mean + radial term +
// seeded pixel-to-pixel scatter, per frequency group.
struct PixelPhasePattern {
  std::array<double, 3> mean_rad{0.0, 0.0, 0.0};
  std::array<double, 3> radial_rad{0.0, 0.0, 0.0};  // at the image corner (r = 1)
  double scatter_rad = 0.0;
  std::uint64_t seed = 1;
};

struct NoiseModel {
  double read_noise = 0.0;  // counts, per raw sample
  double shot_gain = 0.0;   // variance per count of (signal + ambient)
  double ambient = 0.0;     // counts of ambient light per sample (noise only)
};

struct SignalModel {
  double counts_at_1m = 3000.0;  // fundamental amplitude, albedo 1, normal incidence, 1 m
  double saturation = 16320.0;   // |raw| beyond this reads as saturated (32767)
};

// Pinhole intrinsics of the depth camera (nominal Kinect v2 IR values).
struct Camera {
  int width = 512;
  int height = 424;
  double fx = 365.0, fy = 365.0, cx = 256.0, cy = 212.0;
};

// Soft full-well saturation of a tap (docs/simulator-model.md 3.1):
// N(T) = T / (1 + (|T| / W)^p)^(1/p); W = +inf: N(T) = T.
double saturate_tap(double t, double full_well, double sharpness);

struct DeviceProfile {
  std::string name;
  int version = 2;
  double range_ref_mm = 1000.0;          // the range at which curves' fall-off A is 1
  double saturation_sharpness = 8.0;     // p of the taps' soft full well
  std::array<FrequencyModel, 3> groups;  // raw sub-image groups: 80, 16, 120 MHz
  PixelPhasePattern pixel_phase;
  NoiseModel noise;
  SignalModel signal;
  Camera camera;

  // Ideal Kinect v2: 80/16/120 MHz, pure sinusoids, no errors, no noise.
  static DeviceProfile ideal_kinect2();
  void validate() const;  // throws std::invalid_argument

  // The device in one capture session (docs/simulator-model.md 2.2): every group's harmonics
  // become G_h + t_f dG_h for state = (t_80, t_16, t_120); the copy has no drift of its own.
  // Throws std::invalid_argument for a non-finite state or harmonics that leave [0, 1].
  DeviceProfile in_session(const std::array<double, 3>& state) const;
};

}  // namespace tofmat::sim
