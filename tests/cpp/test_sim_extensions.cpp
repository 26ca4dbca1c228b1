// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The model terms the calibration needs beyond the first simulator
// (docs/simulator-model.md, sections marked Extensions): tap full-well
// saturation, signal scales, decode offsets, the double kernel, harmonics above
// 7, version-2 profiles, and multi-threaded rendering that does not change
// frames. The curves of these terms are compared with the calibration's NumPy
// model in tests/python/test_sim_model_parity.py.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <limits>
#include <string>

#include "test_util.hpp"
#include "tofmat/core/decode.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/core/frame_decode.hpp"
#include "tofmat/sim/measurement.hpp"
#include "tofmat/sim/profile_io.hpp"
#include "tofmat/sim/renderer.hpp"
#include "tofmat/sim/stage.hpp"

namespace {

using namespace tofmat::sim;
using cd = std::complex<double>;
constexpr double kTwoPi = 6.283185307179586476925286766559;
constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------
// Taps
// ---------------------------------------------------------------------------

TEST(SaturateTap, IdentityWithoutFullWellAndOddWithIt) {
  for (double t : {-1e6, -3.0, 0.0, 1e-9, 2.5, 1e6}) EXPECT_EQ(saturate_tap(t, kInf, 8.0), t);
  for (double t : {0.1, 0.9, 1.0, 1.7, 40.0}) {
    EXPECT_EQ(saturate_tap(-t, 1.0, 8.0), -saturate_tap(t, 1.0, 8.0)) << t;
  }
}

TEST(SaturateTap, LinearFarBelowAndFlatFarAboveTheWell) {
  const double w = 1000.0, p = 12.0;
  EXPECT_NEAR(saturate_tap(200.0, w, p), 200.0, 200.0 * 1e-8);  // (0.2)^12 / 12 ~ 3e-10
  EXPECT_NEAR(saturate_tap(w, w, p), w * std::pow(2.0, -1.0 / p), 1e-9);
  EXPECT_NEAR(saturate_tap(50.0 * w, w, p), w, 1e-6 * w);  // never above the well
  double prev = 0.0;
  for (int k = 1; k <= 400; ++k) {  // monotonic: more light never reads as less
    const double v = saturate_tap(k * 10.0, w, p);
    EXPECT_GT(v, prev) << k;
    EXPECT_LT(v, w);
    prev = v;
  }
}

TEST(RawSamples, FollowTheTapFormula) {
  FrequencyModel f = DeviceProfile::ideal_kinect2().groups[2];
  f.step_gain = {1.0, 1.03, 0.97};
  f.step_offset = {0.0, 0.02, -0.01};
  f.full_well = 0.8;
  f.harmonic_amplitude[5] = 0.04;
  f.harmonic_phase_rad[5] = 1.1;
  Material m;
  m.kind = ResponseKind::kExponential;
  m.albedo = 0.9;
  m.subsurface = 0.5;
  m.tau_ps = 300.0;
  const auto w = harmonic_weights(f, m, 0.0);
  EXPECT_NEAR(w.dc, 0.9, 1e-15);
  const double range = 777.0, pp = 0.2, signal = 1.4, unit = 2.0, p = 10.0;
  const auto got = raw_samples(f, w, range, pp, signal, unit, p);
  const double x = kTwoPi * f.true_freq_hz() * 1e-9 * 2.0 * range / 299.792458 - pp;
  const double a = signal * f.signal_scale;
  for (std::size_t j = 0; j < 3; ++j) {
    double ac = 0.0;
    for (int h : {1, 5}) {
      ac += (f.harmonic(h) * std::conj(material_response(m, h * f.true_freq_hz(), 0.0)) *
             std::polar(1.0, h * (x + kTwoPi * static_cast<double>(j) / 3.0)))
                .real();
    }
    ac *= a;
    const double dc = a * 0.9, well = 0.8 * unit;
    const auto n = [&](double t) { return t / std::pow(1.0 + std::pow(std::fabs(t) / well, p), 1.0 / p); };
    EXPECT_NEAR(got[j], f.step_gain[j] * (n(0.5 * (dc + ac)) - n(0.5 * (dc - ac))) + f.step_offset[j] * dc, 1e-12) << j;
  }
}

TEST(RawSamples, SlabDcIsTheLightThatComesBack) {
  Material m;
  m.kind = ResponseKind::kSlab;
  m.albedo = 0.5;
  m.subsurface = 1.0;
  m.tau_ps = 1000.0;
  m.thickness_mm = 1.0;
  m.backing = 0.0;
  const auto w = harmonic_weights(DeviceProfile::ideal_kinect2().groups[0], m, 0.0);
  const double transit = 2.0 * 1.0 * 1.5 / 299.792458e9;
  EXPECT_NEAR(w.dc, 0.5 * (1.0 - std::exp(-transit / 1e-9)), 1e-12);  // R(0) = rho (1 - e^{-T/tau})
}

// ---------------------------------------------------------------------------
// Double kernel
// ---------------------------------------------------------------------------

TEST(DoubleKernel, IsTwoExponentialsSharingTheFresnelShare) {
  Material m;
  m.kind = ResponseKind::kDouble;
  m.albedo = 0.4;
  m.subsurface = 0.5;
  m.tau_ps = 150.0;
  m.subsurface2 = 0.1;
  m.tau2_ps = 3000.0;
  m.validate();
  for (double f : {0.0, 16e6, 120e6, 1.56e9}) {
    for (double inc_deg : {0.0, 40.0, 80.0}) {
      const double inc = inc_deg * kTwoPi / 360.0;
      const double t = (1.0 - schlick_reflectance(1.5, inc)) / (1.0 - schlick_reflectance(1.5, 0.0));
      const double w = kTwoPi * f;
      const cd want =
          0.4 * ((1.0 - 0.5 * t - 0.1 * t) + 0.5 * t / cd(1.0, w * 150e-12) + 0.1 * t / cd(1.0, w * 3000e-12));
      EXPECT_NEAR(std::abs(material_response(m, f, inc) - want), 0.0, 1e-14) << f << " " << inc_deg;
    }
  }
  m.subsurface2 = 0.6;  // b + b2 > 1
  EXPECT_THROW(m.validate(), std::invalid_argument);
  m.subsurface2 = 0.1;
  m.tau2_ps = 0.0;
  EXPECT_THROW(m.validate(), std::invalid_argument);
}

// ---------------------------------------------------------------------------
// Decode offsets
// ---------------------------------------------------------------------------

TEST(DecodeOffset, ShiftsEachGroupsDepthByItsPhase) {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  Material m;  // opaque
  std::array<HarmonicWeights, 3> w;
  for (std::size_t g = 0; g < 3; ++g) w[g] = harmonic_weights(d.groups[g], m, 0.0);
  const auto before = ideal_depths(d, w, 900.0);
  const double eps[3] = {0.09, -0.01, -0.08};
  for (std::size_t g = 0; g < 3; ++g) d.groups[g].decode_offset_rad = eps[g];
  const auto after = ideal_depths(d, w, 900.0);
  for (std::size_t g = 0; g < 3; ++g) {
    const double shift = eps[g] * 300.0 / (2.0 * kTwoPi * d.groups[g].freq_mhz * 1e-3);  // C_DEV eps / (4 pi f)
    EXPECT_NEAR(after[g] - before[g], shift, 1e-9) << g;
  }
}

TEST(DecodeOffset, TheDeviceReportsItInItsP0TablesAndTheStageSeesIt) {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.camera.width = 64;
  d.camera.height = 48;
  d.camera.cx = 32.0;
  d.camera.cy = 24.0;
  d.pixel_phase.mean_rad = {0.1, 0.2, -0.3};
  d.pixel_phase.scatter_rad = 0.01;
  MaterialLibrary lib;
  lib.name = "lib";
  Material m;
  m.name = "white";
  m.albedo = 0.9;
  lib.materials.push_back(m);
  Target t;
  t.material = "white";
  t.x0 = 22;
  t.y0 = 14;
  t.x1 = 42;
  t.y1 = 34;
  const PixelRect roi{27, 19, 37, 29};
  const Renderer plain(d, lib);
  const auto a = stage_sweep(plain, t, roi, {800.0, 1100.0}, 1, 5, false);
  const double eps[3] = {0.05, -0.02, 0.07};
  for (std::size_t g = 0; g < 3; ++g) d.groups[g].decode_offset_rad = eps[g];
  const Renderer offset(d, lib);
  for (int g = 0; g < 3; ++g) {
    const auto p0 = offset.p0_table(g);
    const auto& pp = offset.pixel_phase(g);
    for (std::size_t i = 0; i < p0.size(); i += 97) {
      EXPECT_FLOAT_EQ(p0[i], -(pp[i] + static_cast<float>(eps[g]))) << g << " " << i;
    }
  }
  const auto b = stage_sweep(offset, t, roi, {800.0, 1100.0}, 1, 5, false);
  for (std::size_t g = 0; g < 3; ++g) {
    const double shift = eps[g] * 300.0 / (2.0 * kTwoPi * d.groups[g].freq_mhz * 1e-3);
    for (std::size_t k = 0; k < 2; ++k) {
      // raw samples identical, only the P0 tables differ (float32 tables: ~1e-7 rad)
      EXPECT_NEAR(b.depth_mm[g][k] - a.depth_mm[g][k], shift, 2e-3) << g << " " << k;
    }
  }
  EXPECT_THROW(static_cast<void>(offset.p0_table(3)), std::invalid_argument);
}

// ---------------------------------------------------------------------------
// Renderer: saturating taps, threads
// ---------------------------------------------------------------------------

MaterialLibrary two_materials() {
  MaterialLibrary lib;
  lib.name = "lib";
  Material a;
  a.name = "white";
  a.albedo = 0.9;
  Material b;
  b.name = "wax";
  b.kind = ResponseKind::kDouble;
  b.albedo = 0.4;
  b.subsurface = 0.5;
  b.tau_ps = 200.0;
  b.subsurface2 = 0.05;
  b.tau2_ps = 2000.0;
  lib.materials = {a, b};
  return lib;
}

Scene busy_scene() {
  Scene s;
  Target a;
  a.material = "white";
  a.depth_mm = 700.0;
  a.yaw_deg = 20.0;
  a.x0 = 10;
  a.y0 = 10;
  a.x1 = 300;
  a.y1 = 200;
  Target b = a;
  b.material = "wax";
  b.depth_mm = 1000.0;
  b.fold_deg = 60.0;
  b.x0 = 200;
  b.y0 = 150;
  b.x1 = 500;
  b.y1 = 400;
  s.targets = {a, b};
  s.background_material = "white";
  return s;
}

TEST(RendererThreads, FramesDoNotDependOnTheNumberOfThreads) {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.noise.read_noise = 3.0;
  d.noise.shot_gain = 0.03;
  d.groups[1].full_well = 1.0;
  const Renderer one(d, two_materials(), 1), three(d, two_materials(), 3);
  const Scene s = busy_scene();
  const Frame a = one.render(s, 42), b = three.render(s, 42), c = three.render(s, 43);
  EXPECT_EQ(a.raw, b.raw);
  EXPECT_NE(a.raw, c.raw);
  const PixelRect roi{100, 50, 420, 300};
  EXPECT_EQ(one.render_region(s, 7, true, roi).raw, three.render_region(s, 7, true, roi).raw);
  EXPECT_THROW(Renderer(d, two_materials(), -1), std::invalid_argument);
  EXPECT_THROW(Renderer(d, two_materials(), 257), std::invalid_argument);
}

TEST(RendererSaturation, ClipsBrightNearTargetsAndMovesTheirPhase) {
  // A bright target at 500 mm: taps 4x the 1 m signal. With a full well at the
  // 1 m level the samples compress; without one they do not.
  DeviceProfile lin = DeviceProfile::ideal_kinect2();
  lin.signal.counts_at_1m = 2000.0;
  DeviceProfile sat = lin;
  for (auto& g : sat.groups) g.full_well = 1.0;
  sat.saturation_sharpness = 8.0;
  Scene s;
  Target t;
  t.material = "white";
  t.depth_mm = 500.0;
  t.x0 = 236;
  t.y0 = 192;
  t.x1 = 276;
  t.y1 = 232;
  s.targets = {t};
  const PixelRect roi{246, 202, 266, 222};
  const Frame a = Renderer(lin, two_materials()).render_region(s, 1, false, roi);
  const Frame b = Renderer(sat, two_materials()).render_region(s, 1, false, roi);
  double max_a = 0.0, max_b = 0.0;
  for (std::size_t k = 0; k < a.raw.size(); ++k) {
    max_a = std::max(max_a, std::fabs(static_cast<double>(a.raw[k])));
    max_b = std::max(max_b, std::fabs(static_cast<double>(b.raw[k])));
  }
  const double well = 2000.0;  // full_well 1 in counts, range_ref 1000 mm
  EXPECT_GT(max_a, 2.0 * well);
  EXPECT_LT(max_b, well);  // |N(T+) - N(T-)| < W
  // An odd compression of a cosine adds harmonics 5, 7, ... that alias into
  // the 3-step decode: the saturated phase moves (spec 3.1), the linear one
  // decodes to the range.
  const std::size_t n = a.range_mm.size();
  std::vector<float> p0(3 * n, 0.0f);
  const auto da = tofmat::decode_frame(a.raw.data(), n, p0);
  const auto db = tofmat::decode_frame(b.raw.data(), n, p0);
  double moved = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_NEAR(da.depth_mm[2][i], a.range_mm[i] * 300.0 / 299.792458, 1.0) << i;
    moved = std::max(moved, static_cast<double>(std::fabs(db.depth_mm[2][i] - da.depth_mm[2][i])));
  }
  EXPECT_GT(moved, 1.0);
}

// ---------------------------------------------------------------------------
// Version-2 profiles
// ---------------------------------------------------------------------------

TEST(ProfileV2, RoundTripsEveryNewKey) {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.name = "v2";
  d.range_ref_mm = 950.0;
  d.saturation_sharpness = 17.5;
  d.groups[0].full_well = 0.75;
  d.groups[1].signal_scale = 1.0;
  d.groups[2].decode_offset_rad = -0.0825;
  d.groups[2].harmonic_amplitude[13] = 0.0078125;
  d.groups[2].harmonic_phase_rad[13] = -0.5;
  d.groups[1].harmonic_amplitude[16] = 0.25;
  const DeviceProfile back = device_from_json(device_to_json(d));
  EXPECT_EQ(back.range_ref_mm, 950.0);
  EXPECT_EQ(back.saturation_sharpness, 17.5);
  EXPECT_EQ(back.groups[0].full_well, 0.75);
  EXPECT_TRUE(std::isinf(back.groups[1].full_well));  // written as null
  EXPECT_EQ(back.groups[1].signal_scale, 1.0);
  EXPECT_EQ(back.groups[0].signal_scale, d.groups[0].signal_scale);
  EXPECT_EQ(back.groups[2].decode_offset_rad, -0.0825);
  EXPECT_EQ(back.groups[2].harmonic_amplitude[13], 0.0078125);
  EXPECT_EQ(back.groups[2].harmonic_phase_rad[13], -0.5);
  EXPECT_EQ(back.groups[1].harmonic_amplitude[16], 0.25);
  EXPECT_NE(device_to_json(d).find("\"full_well\": null"), std::string::npos);

  Material m;
  m.name = "wood";
  m.kind = ResponseKind::kDouble;
  m.subsurface = 0.4;
  m.tau_ps = 170.0;
  m.subsurface2 = 0.02;
  m.tau2_ps = 3100.0;
  m.noise_mm = 12.5;
  m.albedo = 1.5;  // a specular metal may exceed 1
  const Material mb = material_from_json(material_to_json(m));
  EXPECT_EQ(mb.kind, ResponseKind::kDouble);
  EXPECT_EQ(mb.subsurface2, 0.02);
  EXPECT_EQ(mb.tau2_ps, 3100.0);
  EXPECT_EQ(mb.noise_mm, 12.5);
  EXPECT_EQ(mb.albedo, 1.5);
}

TEST(ProfileV2, ReadsVersion1WithDefaultsAndRejectsBadNewValues) {
  const std::string freqs = R"("frequencies": [{"freq_mhz": 80}, {"freq_mhz": 16}, {"freq_mhz": 120}])";
  const DeviceProfile v1 = device_from_json(R"({"name": "old", "version": 1, )" + freqs + "}");
  EXPECT_EQ(v1.range_ref_mm, 1000.0);
  for (std::size_t g = 0; g < 3; ++g) {
    EXPECT_EQ(v1.groups[g].signal_scale, kDefaultSignalScale[g]);
    EXPECT_TRUE(std::isinf(v1.groups[g].full_well));
    EXPECT_EQ(v1.groups[g].decode_offset_rad, 0.0);
  }
  const auto bad = [&](const std::string& group0, const std::string& top = "") {
    const std::string text = R"({"name": "x", "version": 2, )" + top + R"("frequencies": [{"freq_mhz": 80, )" + group0 +
                             R"(}, {"freq_mhz": 16}, {"freq_mhz": 120}]})";
    try {
      device_from_json(text);
    } catch (const tofmat::FormatError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_CONTAINS(bad(R"("full_well": 0)"), "full_well");
  EXPECT_CONTAINS(bad(R"("full_well": -1)"), "full_well");
  EXPECT_CONTAINS(bad(R"("full_well": "big")"), "full_well");
  EXPECT_CONTAINS(bad(R"("signal_scale": 0)"), "signal_scale");
  EXPECT_CONTAINS(bad(R"("decode_offset_rad": "x")"), "decode_offset_rad");
  EXPECT_CONTAINS(bad(R"("signal_scale": 1)", R"("saturation": {"sharpness": 0.5}, )"), "sharpness");
  EXPECT_CONTAINS(bad(R"("signal_scale": 1)", R"("saturation": {"p": 8}, )"), "'p'");
  EXPECT_CONTAINS(bad(R"("signal_scale": 1)", R"("range_ref_mm": 0, )"), "range_ref_mm");
  EXPECT_TRUE(bad(R"("full_well": null)").empty());
}

}  // namespace
