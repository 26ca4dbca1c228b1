// The float decode (firmware/core decode.hpp, frame_decode.hpp): three phase
// steps to a phasor and phase, hierarchical unwrapping, the per-frame decode
// with its saturated/dark flags, and the simulator's noise-free samples
// decoded at the phase-wrap depths (docs/simulator-model.md section 3,
// shared/docs/kinect2-protocol.md section 3).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/features.hpp"
#include "tofmat/core/frame_decode.hpp"
#include "tofmat/core/raw_lut.hpp"
#include "tofmat/sim/device.hpp"
#include "tofmat/sim/material.hpp"
#include "tofmat/sim/measurement.hpp"

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;
constexpr double kCTrue = 299.792458;  // mm/ns, the physics
constexpr double kCDev = 300.0;        // mm/ns, the decode (Eq. (1))
const std::array<double, 3> kFreqs = {80.0, 16.0, 120.0};
const std::array<double, 3> kWrapDev = {1875.0, 9375.0, 1250.0};  // c_dev / (2 f)

// |a - b| on a circle of circumference r.
double circ(double a, double b, double r) { return std::fabs(std::remainder(a - b, r)); }

// Samples of a pure sinusoid of phase psi: m_j = A cos(psi + phi_j), whose
// phasor sum_j m_j exp(-i phi_j) is 1.5 A exp(i psi).
std::array<double, 3> cos_samples(double amplitude, double psi) {
  std::array<double, 3> m{};
  for (int j = 0; j < 3; ++j) m[static_cast<std::size_t>(j)] = amplitude * std::cos(psi + kTwoPi * j / 3.0);
  return m;
}

// ---------------------------------------------------------------------------
// phasor_from_samples / phase_of
// ---------------------------------------------------------------------------

TEST(Phasor, PhaseStepsAreThoseOfTheProtocol) {
  // 0, 2.094395, 4.18879 rad (protocol 3.2, rounded there to 7 digits).
  EXPECT_EQ(tofmat::kPhaseStepsRad[0], 0.0);
  EXPECT_NEAR(tofmat::kPhaseStepsRad[1], 2.094395, 1e-6);
  EXPECT_NEAR(tofmat::kPhaseStepsRad[2], 4.18879, 1e-5);
}

TEST(Phasor, RecoversThePhaseOfCosineSamplesOverTheWholeCircle) {
  // Tolerance 1e-12 rad: the samples and the phasor are a few roundings of
  // O(A) values, i.e. a relative error of ~1e-15 of the phasor.
  std::vector<double> phases;
  for (int k = 0; k < 2000; ++k) phases.push_back(kTwoPi * k / 2000.0);
  for (double p : {0.0, 1e-300, 1e-15, 1e-9, kPi, kTwoPi - 1e-6, kTwoPi - 1e-9, kTwoPi - 1e-12,
                   std::nextafter(kTwoPi, 0.0)}) {
    phases.push_back(p);
  }
  for (double amplitude : {1.0, 1000.0, 16320.0}) {
    for (double psi : phases) {
      const auto m = cos_samples(amplitude, psi);
      const auto z = tofmat::phasor_from_samples(m.data(), 0.0);
      EXPECT_NEAR(std::abs(z), 1.5 * amplitude, 1e-12 * amplitude) << psi;
      const double p = tofmat::phase_of(z);
      ASSERT_TRUE(std::isfinite(p));
      EXPECT_GE(p, 0.0) << psi;
      EXPECT_LT(p, kTwoPi) << psi;
      EXPECT_LT(circ(p, psi, kTwoPi), 1e-12) << "psi " << psi << " A " << amplitude;
    }
  }
}

TEST(Phasor, ExactlyZeroPhaseGivesZeroOrJustBelowTwoPiNeverTwoPi) {
  const auto m = cos_samples(1000.0, 0.0);
  const double p = tofmat::phase_of(tofmat::phasor_from_samples(m.data(), 0.0));
  EXPECT_LT(circ(p, 0.0, kTwoPi), 1e-12);
  EXPECT_LT(p, kTwoPi);
  // (1, -0.5, -0.5) exactly: the imaginary part cancels to a rounding error.
  const double exact[3] = {2.0, -1.0, -1.0};
  const double q = tofmat::phase_of(tofmat::phasor_from_samples(exact, 0.0));
  EXPECT_LT(circ(q, 0.0, kTwoPi), 1e-15);
  EXPECT_GE(q, 0.0);
  EXPECT_LT(q, kTwoPi);
}

TEST(Phasor, PerPixelCorrectionSubtractsP0) {
  // theta_j = p0 + phi_j: the decoded phase is psi - p0 (mod 2 pi).
  for (double psi : {0.0, 0.3, 2.0, 5.9}) {
    for (double p0 : {-3.0, -0.1, 0.0, 0.7, 6.0}) {
      const auto m = cos_samples(500.0, psi);
      const double p = tofmat::phase_of(tofmat::phasor_from_samples(m.data(), p0));
      EXPECT_LT(circ(p, psi - p0, kTwoPi), 1e-12) << psi << " " << p0;
    }
  }
}

TEST(Phasor, ThirdHarmonicAndCommonOffsetCancel) {
  // A constant added to all three steps and the 3rd harmonic are invisible to the 3-step phasor.
  const double psi = 1.234;
  auto m = cos_samples(800.0, psi);
  for (int j = 0; j < 3; ++j) m[static_cast<std::size_t>(j)] += 55.0 + 100.0 * std::cos(3.0 * (psi + kTwoPi * j / 3.0));
  const auto z = tofmat::phasor_from_samples(m.data(), 0.0);
  EXPECT_NEAR(std::abs(z), 1200.0, 1e-9);
  EXPECT_NEAR(tofmat::phase_of(z), psi, 1e-12);
}

TEST(Phasor, PhaseOfAxesAndZero) {
  EXPECT_EQ(tofmat::phase_of({1.0, 0.0}), 0.0);
  EXPECT_DOUBLE_EQ(tofmat::phase_of({0.0, 1.0}), kPi / 2);
  EXPECT_DOUBLE_EQ(tofmat::phase_of({-1.0, 0.0}), kPi);
  EXPECT_DOUBLE_EQ(tofmat::phase_of({0.0, -1.0}), 1.5 * kPi);
  EXPECT_EQ(tofmat::phase_of({0.0, 0.0}), 0.0);  // "a zero phasor gives 0"
  const double tiny_below = tofmat::phase_of({1.0, -1e-300});  // atan2 = -1e-300 -> 2 pi rounds: must give 0
  EXPECT_GE(tiny_below, 0.0);
  EXPECT_LT(tiny_below, kTwoPi);
}

TEST(Phasor, SignedZeroPhasorIsStillZero) {
  // The contract is "a zero phasor gives 0"; -0.0 is a zero. atan2(+-0, -0) = +-pi,
  // so without care these come back as pi.
  EXPECT_EQ(tofmat::phase_of({-0.0, 0.0}), 0.0);
  EXPECT_EQ(tofmat::phase_of({-0.0, -0.0}), 0.0);
  EXPECT_EQ(tofmat::phase_of({0.0, -0.0}), 0.0);
}

// ---------------------------------------------------------------------------
// unwrap_depths
// ---------------------------------------------------------------------------

std::array<double, 3> wrapped(double depth) {
  std::array<double, 3> d{};
  for (std::size_t g = 0; g < 3; ++g) d[g] = std::fmod(depth, kWrapDev[g]);
  return d;
}

TEST(Unwrap, RecoversTrueDepthsFrom0To9000mmNoiseFree) {
  // 0.25 mm steps: 36001 depths. Tolerance 1e-9 mm (fmod is exact; the
  // re-added multiples and the weighted mean are a few roundings of ~1e4).
  for (int k = 0; k <= 36000; ++k) {
    const double depth = 0.25 * k;
    const auto u = tofmat::unwrap_depths(wrapped(depth));
    for (std::size_t g = 0; g < 3; ++g) ASSERT_NEAR(u.depth_mm[g], depth, 1e-9) << depth << " group " << g;
    ASSERT_NEAR(u.combined_mm, depth, 1e-9) << depth;
  }
}

TEST(Unwrap, WrappedValuesJustBelowTheWavelengthUnwrapToTheSameDepth) {
  // A depth at a multiple of a wavelength may be decoded as 0 or as r - tiny.
  for (double depth : {1250.0, 1875.0, 2500.0, 3750.0, 5625.0, 7500.0}) {
    auto d = wrapped(depth);
    for (std::size_t g = 0; g < 3; ++g) {
      if (d[g] == 0.0 && depth > 0.0) d[g] = kWrapDev[g] - 1e-9;
    }
    const auto u = tofmat::unwrap_depths(d);
    EXPECT_NEAR(u.combined_mm, depth, 1e-6) << depth;
  }
}

TEST(Unwrap, Documented937mmToleranceOfD16) {
  // D80 = d80 + 1875 round((D16 - d80) / 1875): an error e of D16 is harmless
  // while |e| < 937.5 mm, then D80 (and with it D120) jumps by 1875 mm.
  for (double depth : {1000.0, 3000.0, 4321.0, 7000.0}) {
    for (double e : {-937.0, 937.0}) {
      auto d = wrapped(depth);
      d[1] += e;
      const auto u = tofmat::unwrap_depths(d);
      EXPECT_NEAR(u.depth_mm[0], depth, 1e-9) << depth << " e " << e;
      EXPECT_NEAR(u.depth_mm[2], depth, 1e-9) << depth << " e " << e;
      EXPECT_NEAR(u.combined_mm, depth + 16.0 * e / 216.0, 1e-9);
    }
    for (double e : {-938.0, 938.0}) {
      auto d = wrapped(depth);
      d[1] += e;
      const auto u = tofmat::unwrap_depths(d);
      EXPECT_NEAR(u.depth_mm[0], depth + std::copysign(1875.0, e), 1e-9) << "fails here by design: " << depth << " " << e;
    }
  }
}

TEST(Unwrap, Documented625mmToleranceOfD80) {
  for (double depth : {1000.0, 3000.0, 7000.0}) {
    for (double e : {-624.0, 624.0}) {
      auto d = wrapped(depth);
      d[0] = std::fmod(depth + e + 1875.0, 1875.0);
      EXPECT_NEAR(tofmat::unwrap_depths(d).depth_mm[2], depth, 1e-9) << depth << " " << e;
    }
    for (double e : {-626.0, 626.0}) {
      auto d = wrapped(depth);
      d[0] = std::fmod(depth + e + 1875.0, 1875.0);
      EXPECT_NEAR(tofmat::unwrap_depths(d).depth_mm[2], depth + std::copysign(1250.0, e), 1e-9) << depth << " " << e;
    }
  }
}

TEST(Unwrap, BeyondTheUnambiguousRangeTheCombinedDepthIsWrong) {
  // 9375 mm (the 16 MHz half wavelength) is the documented unambiguous range.
  // Beyond it the result is not even D - 9375: 9375 = 7.5 x 1250, so D120's
  // multiple is off by exactly half a 120 MHz wavelength (round(k + 0.5)),
  // and the combined depth is off by 120 * 625 / 216 = 347.2 mm on top of
  // the fold. (The Kinect's own unwrapping reaches 18750 mm, protocol 3.3.)
  for (double depth : {9375.0, 9400.0, 12000.0}) {
    const double comb = tofmat::unwrap_depths(wrapped(depth)).combined_mm;
    EXPECT_NEAR(std::fabs(comb - (depth - 9375.0)), 120.0 * 625.0 / 216.0, 1e-6) << depth;
  }
  // Just inside the range it is still exact.
  EXPECT_NEAR(tofmat::unwrap_depths(wrapped(9374.75)).combined_mm, 9374.75, 1e-9);
}

// ---------------------------------------------------------------------------
// decode_frame
// ---------------------------------------------------------------------------

// A raw frame of `pixels` pixels, 9 x pixels sub-image-major, all zero.
struct RawFrame {
  std::size_t pixels;
  std::vector<std::int16_t> raw;
  explicit RawFrame(std::size_t n) : pixels(n), raw(9 * n, 0) {}
  void set(std::size_t px, std::size_t g, const std::array<double, 3>& m) {
    for (std::size_t j = 0; j < 3; ++j) raw[(g * 3 + j) * pixels + px] = static_cast<std::int16_t>(std::lround(m[j]));
  }
  std::int16_t& at(std::size_t px, std::size_t g, std::size_t j) { return raw[(g * 3 + j) * pixels + px]; }
};

TEST(DecodeFrame, FlagsSaturatedAndDarkPixelsAndKeepsValidOnes) {
  RawFrame f(6);
  const double depth = 1111.0;
  auto psi = [&](std::size_t g) { return kTwoPi * std::fmod(depth, kWrapDev[g]) / kWrapDev[g]; };
  for (std::size_t px = 0; px < 6; ++px) {
    for (std::size_t g = 0; g < 3; ++g) f.set(px, g, cos_samples(4000.0, psi(g)));
  }
  f.at(1, 2, 1) = tofmat::kRawSaturated;  // one saturated sample in group 120 MHz
  for (std::size_t g = 0; g < 3; ++g) f.set(2, g, {0.0, 0.0, 0.0});  // no signal
  f.set(3, 1, {2.0, -1.0, -1.0});                                   // 16 MHz amplitude 2 < 3
  f.set(4, 0, {4.0, -2.0, -2.0});                                   // amplitude 4 >= 3: valid
  f.set(5, 1, {0.0, 0.0, 0.0});
  f.at(5, 0, 0) = tofmat::kRawSaturated;  // saturated and dark

  const auto out = tofmat::decode_frame(f.raw.data(), f.pixels, {});
  ASSERT_EQ(out.pixels, 6u);
  ASSERT_EQ(out.flags.size(), 6u);
  EXPECT_EQ(out.flags[0], 0);
  EXPECT_EQ(out.flags[1], tofmat::kDecodeSaturated);
  EXPECT_EQ(out.flags[2], tofmat::kDecodeDark);
  EXPECT_EQ(out.flags[3], tofmat::kDecodeDark);
  EXPECT_EQ(out.flags[4], 0);
  EXPECT_EQ(out.flags[5], tofmat::kDecodeSaturated | tofmat::kDecodeDark);

  // Valid pixels: amplitudes |z| / 1.5, depths of Eq. (1), combined unwrapped.
  // Integer rounding of 4000-count samples moves the phase by <= 1.5 / 6000
  // rad: < 0.3 mm at 16 MHz (9375 / 2 pi * 2.5e-4), tolerance 0.5 mm.
  for (std::size_t px : {0u, 4u}) {
    for (std::size_t g = 0; g < 3; ++g) {
      if (px == 4 && g == 0) continue;
      EXPECT_NEAR(out.amplitude[g][px], 4000.0, 2.0);
      EXPECT_LT(circ(out.depth_mm[g][px], depth, kWrapDev[g]), 0.5) << px << " " << g;
    }
    EXPECT_TRUE(std::isfinite(out.combined_mm[px]));
  }
  EXPECT_NEAR(out.combined_mm[0], depth, 0.1);
  EXPECT_NEAR(out.amplitude[0][4], 4.0, 1e-6);
  EXPECT_NEAR(out.phase_rad[0][4], 0.0, 1e-6);
  EXPECT_NEAR(out.amplitude[1][3], 2.0, 1e-6);

  // Flagged pixels: NaN depths, never a number that could be mistaken for a range.
  for (std::size_t px : {1u, 2u, 3u, 5u}) {
    EXPECT_TRUE(std::isnan(out.combined_mm[px])) << px;
    for (std::size_t g = 0; g < 3; ++g) EXPECT_TRUE(std::isnan(out.depth_mm[g][px])) << px << " " << g;
  }
  // Phases and amplitudes are always finite, [0, 2 pi).
  for (std::size_t g = 0; g < 3; ++g) {
    for (std::size_t px = 0; px < 6; ++px) {
      EXPECT_TRUE(std::isfinite(out.amplitude[g][px]));
      EXPECT_GE(out.phase_rad[g][px], 0.0f);
      EXPECT_LT(out.phase_rad[g][px], static_cast<float>(kTwoPi));
    }
  }
}

TEST(DecodeFrame, MinAmplitudeOption) {
  RawFrame f(1);
  for (std::size_t g = 0; g < 3; ++g) f.set(0, g, {20.0, -10.0, -10.0});  // amplitude 20
  tofmat::DecodeOptions o;
  o.min_amplitude = 19.9;
  EXPECT_EQ(tofmat::decode_frame(f.raw.data(), 1, {}, o).flags[0], 0);
  o.min_amplitude = 20.1;
  EXPECT_EQ(tofmat::decode_frame(f.raw.data(), 1, {}, o).flags[0], tofmat::kDecodeDark);
}

TEST(DecodeFrame, AppliesP0PerPixelAndGroup) {
  RawFrame f(2);
  const std::array<double, 3> psi = {1.0, 2.0, 3.0};
  for (std::size_t px = 0; px < 2; ++px) {
    for (std::size_t g = 0; g < 3; ++g) f.set(px, g, cos_samples(10000.0, psi[g]));
  }
  // p0 layout: 3 x pixels (group-major).
  const std::vector<float> p0 = {0.0f, 0.5f, 0.0f, -0.25f, 0.0f, 1.0f};
  const auto out = tofmat::decode_frame(f.raw.data(), 2, p0);
  for (std::size_t g = 0; g < 3; ++g) {
    EXPECT_LT(circ(out.phase_rad[g][0], psi[g], kTwoPi), 2e-4) << g;  // int rounding: <= 1.5 / 15000 rad
    EXPECT_LT(circ(out.phase_rad[g][1], psi[g] - p0[g * 2 + 1], kTwoPi), 2e-4) << g;
  }
  EXPECT_THROW(tofmat::decode_frame(f.raw.data(), 2, std::vector<float>(5, 0.0f)), std::invalid_argument);
  EXPECT_THROW(tofmat::decode_frame(f.raw.data(), 2, std::vector<float>(2, 0.0f)), std::invalid_argument);
}

TEST(DecodeFrame, ZeroPixels) {
  const auto out = tofmat::decode_frame(nullptr, 0, {});
  EXPECT_EQ(out.pixels, 0u);
  EXPECT_TRUE(out.flags.empty());
  EXPECT_TRUE(out.combined_mm.empty());
}

// ---------------------------------------------------------------------------
// The simulator's noise-free samples through the decode
// ---------------------------------------------------------------------------

struct IdealSetup {
  tofmat::sim::DeviceProfile device = tofmat::sim::DeviceProfile::ideal_kinect2();
  tofmat::sim::Material opaque;
  std::array<tofmat::sim::HarmonicWeights, 3> w{};
  IdealSetup() {
    opaque.name = "opaque";
    opaque.kind = tofmat::sim::ResponseKind::kOpaque;
    opaque.albedo = 0.7;
    for (std::size_t g = 0; g < 3; ++g) w[g] = tofmat::sim::harmonic_weights(device.groups[g], opaque, 0.0);
  }
};

TEST(IdealDecode, IdealDeviceHasTheKinectFrequencies) {
  const auto d = tofmat::sim::DeviceProfile::ideal_kinect2();
  for (std::size_t g = 0; g < 3; ++g) EXPECT_EQ(d.groups[g].freq_mhz, kFreqs[g]);
  EXPECT_NO_THROW(d.validate());
}

// Decoded depth = range * 300 / 299.792458 (the decode's c against the physics'),
// modulo each frequency's wrap. Tolerance 1e-6 mm: the samples are exact to
// ~1e-15 relative and the phase (up to ~50 rad) to ~1e-14 rad, i.e. 1e-11 mm.
TEST(IdealDecode, PhaseWrapDepthsOfEachFrequency) {
  const IdealSetup s;
  const double scale = kCDev / kCTrue;
  for (std::size_t wrap_group = 0; wrap_group < 3; ++wrap_group) {
    const double wrap_true = kCTrue / (2.0 * kFreqs[wrap_group] * 1e-3);  // 1873.7, 9368.5, 1249.1 mm
    for (int k = 0; k * wrap_true < 9369.0; ++k) {
      for (double off : {0.0, -1e-9, 1e-9, -1e-6, 1e-6, -1e-3, 1e-3}) {
        const double range = k * wrap_true + off;
        if (range < 0.0) continue;
        const auto d = tofmat::sim::ideal_depths(s.device, s.w, range);
        for (std::size_t g = 0; g < 3; ++g) {
          ASSERT_TRUE(std::isfinite(d[g])) << range;
          EXPECT_GE(d[g], 0.0);
          EXPECT_LT(d[g], kWrapDev[g]);
          EXPECT_LT(circ(d[g], range * scale, kWrapDev[g]), 1e-6) << "range " << range << " group " << g;
        }
        const auto u = tofmat::unwrap_depths(d);
        ASSERT_TRUE(std::isfinite(u.combined_mm));
        // The combined depth only inside the unambiguous range (9375 mm
        // decoded; at and beyond it see Unwrap.BeyondTheUnambiguousRange...).
        if (range * scale < 9374.99) {
          EXPECT_LT(circ(u.combined_mm, range * scale, 9375.0), 1e-6) << range;
        }
      }
    }
  }
  // The documented values.
  EXPECT_NEAR(kCTrue / (2.0 * 0.120), 1249.1, 0.05);
  EXPECT_NEAR(kCTrue / (2.0 * 0.080), 1873.7, 0.05);
  EXPECT_NEAR(kCTrue / (2.0 * 0.016), 9368.5, 0.05);
}

TEST(IdealDecode, SweepDecodesToScaledRange) {
  const IdealSetup s;
  const double scale = kCDev / kCTrue;
  for (int k = 0; k <= 13000; ++k) {
    const double range = 0.7 * k;  // 0 .. 9100 mm
    const auto d = tofmat::sim::ideal_depths(s.device, s.w, range);
    for (std::size_t g = 0; g < 3; ++g) ASSERT_LT(circ(d[g], range * scale, kWrapDev[g]), 1e-6) << range << " " << g;
    const double comb = tofmat::unwrap_depths(d).combined_mm;
    if (range > 1.0) {
      ASSERT_NEAR(comb, range * scale, 1e-6) << range;
    }
  }
}

TEST(IdealDecode, RawSamplesAreTheCosinesOfTheSpec) {
  // m_j = A r_f Re{conj(R) exp(i (2 pi f t - delta_p + phi_j))} with R = albedo for an opaque material
  // and r_f the group's signal scale.
  const IdealSetup s;
  for (double range : {0.0, 500.0, 1234.5, 8000.0}) {
    for (double dp : {0.0, 0.4}) {
      for (std::size_t g = 0; g < 3; ++g) {
        const auto m = tofmat::sim::raw_samples(s.device.groups[g], s.w[g], range, dp, 1000.0, 1.0, s.device.saturation_sharpness);
        const double x = kTwoPi * kFreqs[g] * 1e-3 * 2.0 * range / kCTrue - dp;
        for (int j = 0; j < 3; ++j) {
          EXPECT_NEAR(m[static_cast<std::size_t>(j)],
                      1000.0 * s.device.groups[g].signal_scale * 0.7 * std::cos(x + kTwoPi * j / 3.0), 1e-9)
              << range << " " << g << " " << j;
        }
      }
    }
  }
}

}  // namespace

// ---------------------------------------------------------------------------
// Region decode and per-pixel features
// ---------------------------------------------------------------------------

TEST(DecodeRegion, EqualsTheFullFrameDecodeOfThosePixelsAndCarriesTheFeatures) {
  const int w = 40, h = 30;
  const std::size_t n = static_cast<std::size_t>(w * h);
  std::vector<std::int16_t> raw(9 * n);
  std::vector<float> p0(3 * n);
  std::uint32_t state = 12345;
  const auto next = [&] { return state = state * 1664525u + 1013904223u; };
  for (auto& v : raw) v = static_cast<std::int16_t>(static_cast<int>(next() % 4001) - 2000);
  for (auto& v : p0) v = static_cast<float>(next() % 1000) * 1e-3f;
  raw[5 * n + 3 * w + 7] = tofmat::kRawSaturated;
  const auto full = tofmat::decode_frame(raw.data(), n, p0);
  const tofmat::PixelRegion r{5, 2, 17, 11};
  const auto part = tofmat::decode_region(raw.data(), w, h, p0, r);
  ASSERT_EQ(part.pixels, 12u * 9u);
  std::size_t k = 0;
  for (int y = r.y0; y < r.y1; ++y) {
    for (int x = r.x0; x < r.x1; ++x, ++k) {
      const std::size_t i = static_cast<std::size_t>(y * w + x);
      ASSERT_EQ(part.flags[k], full.flags[i]);
      for (std::size_t g = 0; g < 3; ++g) ASSERT_EQ(part.phase_rad[g][k], full.phase_rad[g][i]);
      if (full.flags[i]) {
        EXPECT_TRUE(std::isnan(part.features[0][k]));
        continue;
      }
      ASSERT_EQ(part.combined_mm[k], full.combined_mm[i]);
      // Eq. (10) in the database's sign, from the wrapped depths.
      // (from the double depths: within the float rounding of depths up to 9375 mm)
      EXPECT_NEAR(part.features[0][k], full.depth_mm[1][i] - full.depth_mm[2][i], 2e-3);
      EXPECT_NEAR(part.features[1][k], full.depth_mm[0][i] - full.depth_mm[2][i], 2e-3);
    }
  }
  EXPECT_EQ(part.flags[1 * 12 + 2], tofmat::kDecodeSaturated);  // (7, 3) is saturated
  EXPECT_THROW(tofmat::decode_region(raw.data(), w, h, p0, {0, 0, 41, 1}), std::invalid_argument);
  EXPECT_THROW(tofmat::decode_region(raw.data(), w, h, p0, {3, 3, 3, 9}), std::invalid_argument);
  EXPECT_THROW(tofmat::decode_region(raw.data(), w, h, std::vector<float>(5), r), std::invalid_argument);
}
