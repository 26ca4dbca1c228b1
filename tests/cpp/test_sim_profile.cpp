// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Device profiles and material libraries as versioned JSON (firmware/sim
// profile_io.hpp): every malformed input is a tofmat::FormatError naming the
// key; serialisation round-trips exactly. Inputs are JSON text written here by
// hand, never produced by the writer under test.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <fstream>
#include <stdexcept>
#include <string>

#include "test_util.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/sim/device.hpp"
#include "tofmat/sim/material.hpp"
#include "tofmat/sim/profile_io.hpp"

namespace {

using tofmat::FormatError;
using tofmat::sim::device_from_json;
using tofmat::sim::device_to_json;
using tofmat::sim::DeviceProfile;
using tofmat::sim::library_from_json;
using tofmat::sim::library_to_json;
using tofmat::sim::Material;
using tofmat::sim::material_from_json;
using tofmat::sim::MaterialLibrary;
using tofmat::sim::ResponseKind;
using tofmat_test::error_of;

const std::string kFreqs = R"("frequencies": [{"freq_mhz": 80}, {"freq_mhz": 16}, {"freq_mhz": 120}])";

std::string device_json(const std::string& extra = "", const std::string& freqs = kFreqs) {
  return R"({"name": "dev", "version": 1, )" + freqs + (extra.empty() ? "" : ", " + extra) + "}";
}

std::string freqs_with(const std::string& group0_extra) {
  return R"("frequencies": [{"freq_mhz": 80, )" + group0_extra + R"(}, {"freq_mhz": 16}, {"freq_mhz": 120}])";
}

std::string device_error(const std::string& text) {
  return error_of<FormatError>([&] { device_from_json(text); });
}

const std::string kMat = R"({"name": "cork", "kind": "exponential", "albedo": 0.5, "subsurface": 0.3, "tau_ps": 200})";

std::string library_json(const std::string& materials, const std::string& extra = "") {
  return R"({"name": "lib", "version": 1, "materials": [)" + materials + "]" + (extra.empty() ? "" : ", " + extra) +
         "}";
}

std::string library_error(const std::string& text) {
  return error_of<FormatError>([&] { library_from_json(text); });
}

// ---------------------------------------------------------------------------
// Device profiles: accepted
// ---------------------------------------------------------------------------

TEST(DeviceJson, MinimalProfileIsTheIdealDevice) {
  const DeviceProfile d = device_from_json(device_json());
  EXPECT_EQ(d.name, "dev");
  const DeviceProfile ideal = DeviceProfile::ideal_kinect2();
  for (std::size_t g = 0; g < 3; ++g) {
    EXPECT_EQ(d.groups[g].freq_mhz, ideal.groups[g].freq_mhz);
    EXPECT_EQ(d.groups[g].harmonic_amplitude, ideal.groups[g].harmonic_amplitude);
    EXPECT_EQ(d.groups[g].harmonic_phase_rad, ideal.groups[g].harmonic_phase_rad);
    EXPECT_EQ(d.groups[g].step_gain, ideal.groups[g].step_gain);
  }
  EXPECT_EQ(d.noise.read_noise, 0.0);
  EXPECT_EQ(d.camera.width, 512);
}

TEST(DeviceJson, HarmonicsByOrder) {
  const DeviceProfile d = device_from_json(device_json(
      "", freqs_with(R"("harmonics": [{"h": 2, "amplitude": 0.05, "phase_rad": 0.5}, {"h": 7, "amplitude": 0.01}])")));
  EXPECT_EQ(d.groups[0].harmonic_amplitude[2], 0.05);
  EXPECT_EQ(d.groups[0].harmonic_phase_rad[2], 0.5);
  EXPECT_EQ(d.groups[0].harmonic(7), std::complex<double>(0.01, 0.0));
  EXPECT_EQ(d.groups[0].harmonic(1), 1.0);
  EXPECT_EQ(d.groups[0].harmonic(3), 0.0);
  EXPECT_EQ(d.groups[1].harmonic(2), 0.0);
}

// ---------------------------------------------------------------------------
// Device profiles: rejected, naming the key
// ---------------------------------------------------------------------------

TEST(DeviceJson, RejectsUnknownKeysEverywhere) {
  EXPECT_CONTAINS(device_error(device_json(R"("colour": 1)")), "colour");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("freq": 1)"))), "freq'");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("freq": 1)"))), "frequencies[0]");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("harmonics": [{"h": 2, "amp": 0.1}])"))), "amp");
  EXPECT_CONTAINS(device_error(device_json(R"("pixel_phase": {"mean": [0, 0, 0]})")), "mean");
  EXPECT_CONTAINS(device_error(device_json(R"("noise": {"read": 1})")), "read");
  EXPECT_CONTAINS(device_error(device_json(R"("signal": {"counts": 1})")), "counts");
  EXPECT_CONTAINS(device_error(device_json(R"("camera": {"w": 1})")), "'w'");
  EXPECT_NO_THROW(device_from_json(device_json(R"("fit": {"x": 1}, "notes": "free text")")));
}

TEST(DeviceJson, RejectsWrongOrMissingVersion) {
  const std::string body = R"("name": "dev", )" + kFreqs;
  EXPECT_CONTAINS(device_error("{" + body + "}"), "version");
  EXPECT_CONTAINS(device_error(R"({"version": 3, )" + body + "}"), "version");
  EXPECT_CONTAINS(device_error(R"({"version": 0, )" + body + "}"), "version");
  EXPECT_CONTAINS(device_error(R"({"version": "1", )" + body + "}"), "version");
  EXPECT_CONTAINS(device_error(R"({"version": 1.5, )" + body + "}"), "version");
}

TEST(DeviceJson, RejectsMissingOrNonStringName) {
  EXPECT_CONTAINS(device_error(R"({"version": 1, )" + kFreqs + "}"), "name");
  EXPECT_CONTAINS(device_error(R"({"version": 1, "name": 7, )" + kFreqs + "}"), "name");
  EXPECT_CONTAINS(device_error(R"({"version": 1, "name": null, )" + kFreqs + "}"), "name");
}

TEST(DeviceJson, RejectsWrongTypes) {
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("scale_error": "0.1")"))), "scale_error");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("phase_offset_rad": true)"))), "phase_offset_rad");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("step_gain": [1, 1])"))), "step_gain");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("step_gain": [1, "1", 1])"))), "step_gain");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("step_offset": 0)"))), "step_offset");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("harmonics": {"h": 2})"))), "harmonics");
  EXPECT_CONTAINS(
      device_error(device_json("", R"("frequencies": [{"freq_mhz": "80"}, {"freq_mhz": 16}, {"freq_mhz": 120}])")),
      "freq_mhz");
  EXPECT_CONTAINS(device_error(device_json("", R"("frequencies": {"freq_mhz": 80})")), "frequencies");
  EXPECT_CONTAINS(device_error(device_json("", R"("frequencies": [{"freq_mhz": 80}, {"freq_mhz": 16}])")),
                  "frequencies");
  EXPECT_CONTAINS(device_error(device_json("", R"("frequencies": [1, 2, 3])")), "frequencies[0]");
  EXPECT_CONTAINS(device_error(device_json(R"("noise": {"read_noise": null})")), "read_noise");
  EXPECT_CONTAINS(device_error(device_json(R"("noise": [1])")), "noise");
  EXPECT_CONTAINS(device_error(device_json(R"("signal": {"saturation": "max"})")), "saturation");
  EXPECT_CONTAINS(device_error(device_json(R"("camera": {"width": "512"})")), "width");
  EXPECT_CONTAINS(device_error(device_json(R"("pixel_phase": {"radial_rad": 0.1})")), "radial_rad");
  EXPECT_CONTAINS(device_error(device_json(R"("pixel_phase": {"seed": "1"})")), "seed");
}

TEST(DeviceJson, RejectsHarmonicOrderOutside2To32) {
  for (const char* h : {"0", "1", "33", "-2", "2.5", "1e9", "\"2\""}) {
    const std::string text =
        device_json("", freqs_with(std::string(R"("harmonics": [{"h": )") + h + R"(, "amplitude": 0.1}])"));
    EXPECT_CONTAINS(device_error(text), ".h") << "h = " << h;  // "...harmonics.h" or "h must be"
  }
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("harmonics": [{"amplitude": 0.1}])"))), 'h');
  for (int h = 2; h <= 7; ++h) {
    EXPECT_NO_THROW(device_from_json(
        device_json("", freqs_with(R"("harmonics": [{"h": )" + std::to_string(h) + R"(, "amplitude": 0.1}])"))))
        << h;
  }
}

TEST(DeviceJson, RejectsOutOfRangeValuesAsFormatError) {
  EXPECT_CONTAINS(
      device_error(device_json("", R"("frequencies": [{"freq_mhz": -80}, {"freq_mhz": 16}, {"freq_mhz": 120}])")),
      "freq_mhz");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("harmonics": [{"h": 2, "amplitude": 1.5}])"))),
                  "harmonic");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("step_gain": [1, 3, 1])"))), "step gains");
  EXPECT_CONTAINS(device_error(device_json(R"("noise": {"read_noise": -1})")), "noise");
  EXPECT_CONTAINS(device_error(device_json(R"("signal": {"saturation": 20000})")), "saturation");
  EXPECT_CONTAINS(device_error(device_json(R"("camera": {"width": 0})")), "camera");
  EXPECT_CONTAINS(device_error(device_json(R"("camera": {"fx": -1})")), "camera");
}

TEST(DeviceJson, RejectsNonJsonAndNonObjects) {
  EXPECT_FALSE(device_error("{").empty());
  EXPECT_FALSE(device_error("").empty());
  EXPECT_FALSE(device_error("[1, 2]").empty());
  EXPECT_FALSE(device_error(R"({"name": "a", "version": 1, "frequencies": [1e999, 0, 0]})").empty());
  EXPECT_FALSE(device_error(std::string(tofmat::sim::kProfileMaxBytes + 1, ' ')).empty());
}

// A negative amplitude is not an amplitude: std::polar requires rho >= 0 (a
// precondition; libstdc++ asserts it in debug mode), and the profile would
// silently stand for amplitude |a| at phase + pi.
TEST(DeviceJson, RejectsNegativeHarmonicAmplitude) {
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("harmonics": [{"h": 2, "amplitude": -0.05}])"))),
                  "amplitude");
}

// Integer fields read through a double and a static_cast: a fraction is
// silently dropped and a negative or huge value is an undefined conversion.
// A typo must not turn into a different device.
TEST(DeviceJson, RejectsNonIntegerOrOutOfRangeIntegerFields) {
  EXPECT_CONTAINS(device_error(device_json(R"("camera": {"width": 100.7})")), "width");
  EXPECT_CONTAINS(device_error(device_json(R"("camera": {"height": 1e12})")), "height");
  EXPECT_CONTAINS(device_error(device_json(R"("pixel_phase": {"seed": -5})")), "seed");
  EXPECT_CONTAINS(device_error(device_json(R"("pixel_phase": {"seed": 1.5})")), "seed");
}

// ---------------------------------------------------------------------------
// Device profiles: round trip
// ---------------------------------------------------------------------------

DeviceProfile rich_device() {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.name = "rich";
  for (std::size_t g = 0; g < 3; ++g) {
    auto& f = d.groups[g];
    f.scale_error = 1e-4 * (static_cast<double>(g) + 1);
    f.phase_offset_rad = 0.1 + 0.37 * static_cast<double>(g);
    f.step_gain = {1.01, 0.99, 1.0 + 1e-7};
    f.step_offset = {0.001, -0.002, 1.0 / 3.0};
    f.harmonic_amplitude[3] = 0.125;  // exactly representable amplitude, zero phase
    f.harmonic_phase_rad[3] = 0.0;
    f.harmonic_amplitude[5] = 0.0;
  }
  d.pixel_phase.mean_rad = {0.1, -0.2, 0.3};
  d.pixel_phase.radial_rad = {0.01, 0.02, 1.0 / 7.0};
  d.pixel_phase.scatter_rad = 0.003;
  d.pixel_phase.seed = 12345;
  d.noise = {2.5, 0.8, 11.0};
  d.signal = {2718.28, 16000.0};
  d.camera = {320, 240, 250.5, 251.25, 160.125, 119.875};
  return d;
}

void expect_same(const DeviceProfile& a, const DeviceProfile& b) {
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.version, b.version);
  for (std::size_t g = 0; g < 3; ++g) {
    EXPECT_EQ(a.groups[g].freq_mhz, b.groups[g].freq_mhz) << g;
    EXPECT_EQ(a.groups[g].scale_error, b.groups[g].scale_error) << g;
    EXPECT_EQ(a.groups[g].phase_offset_rad, b.groups[g].phase_offset_rad) << g;
    EXPECT_EQ(a.groups[g].step_gain, b.groups[g].step_gain) << g;
    EXPECT_EQ(a.groups[g].step_offset, b.groups[g].step_offset) << g;
    for (std::size_t h = 1; h <= 7; ++h) {
      EXPECT_EQ(a.groups[g].harmonic(static_cast<int>(h)), b.groups[g].harmonic(static_cast<int>(h)))
          << "group " << g << " h " << h;
    }
  }
  EXPECT_EQ(a.pixel_phase.mean_rad, b.pixel_phase.mean_rad);
  EXPECT_EQ(a.pixel_phase.radial_rad, b.pixel_phase.radial_rad);
  EXPECT_EQ(a.pixel_phase.scatter_rad, b.pixel_phase.scatter_rad);
  EXPECT_EQ(a.pixel_phase.seed, b.pixel_phase.seed);
  EXPECT_EQ(a.noise.read_noise, b.noise.read_noise);
  EXPECT_EQ(a.noise.shot_gain, b.noise.shot_gain);
  EXPECT_EQ(a.noise.ambient, b.noise.ambient);
  EXPECT_EQ(a.signal.counts_at_1m, b.signal.counts_at_1m);
  EXPECT_EQ(a.signal.saturation, b.signal.saturation);
  EXPECT_EQ(a.camera.width, b.camera.width);
  EXPECT_EQ(a.camera.height, b.camera.height);
  EXPECT_EQ(a.camera.fx, b.camera.fx);
  EXPECT_EQ(a.camera.fy, b.camera.fy);
  EXPECT_EQ(a.camera.cx, b.camera.cx);
  EXPECT_EQ(a.camera.cy, b.camera.cy);
}

TEST(DeviceJson, RoundTripIsExact) {
  const DeviceProfile d = rich_device();
  const std::string text = device_to_json(d);
  const DeviceProfile back = device_from_json(text);
  expect_same(d, back);
  EXPECT_EQ(device_to_json(back), text);  // a fixed point
}

TEST(DeviceJson, IdealDeviceRoundTrips) {
  const DeviceProfile d = DeviceProfile::ideal_kinect2();
  expect_same(d, device_from_json(device_to_json(d)));
}

// Harmonics are stored as (amplitude, phase) and rebuilt with std::polar:
// general complex values must still come back bit for bit.
TEST(DeviceJson, RoundTripOfGeneralHarmonicsIsExact) {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.name = "harmonics";
  int k = 0;
  for (std::size_t g = 0; g < 3; ++g) {
    for (std::size_t h = 2; h <= 7; ++h, ++k) {
      d.groups[g].harmonic_amplitude[h] = 0.01 + 0.013 * k;
      d.groups[g].harmonic_phase_rad[h] = -3.0 + 0.37 * k;
    }
  }
  const DeviceProfile back = device_from_json(device_to_json(d));
  for (std::size_t g = 0; g < 3; ++g) {
    for (std::size_t h = 2; h <= 7; ++h) {
      EXPECT_EQ(back.groups[g].harmonic_amplitude[h], d.groups[g].harmonic_amplitude[h]) << g << " " << h;
      EXPECT_EQ(back.groups[g].harmonic_phase_rad[h], d.groups[g].harmonic_phase_rad[h]) << g << " " << h;
    }
  }
  // Written as JSON by hand, read, written and read again: the second read must equal the first.
  const DeviceProfile once =
      device_from_json(device_json("", freqs_with(R"("harmonics": [{"h": 2, "amplitude": 0.05, "phase_rad": 0.3}])")));
  const DeviceProfile twice = device_from_json(device_to_json(once));
  EXPECT_EQ(twice.groups[0].harmonic(2), once.groups[0].harmonic(2));
}

// Session drift (docs/simulator-model.md 2.2): parsed like the harmonics, written only when
// present, and a session moves every group's G_h by t_f dG_h.
TEST(DeviceJson, SessionDriftParsesAndRoundTrips) {
  const DeviceProfile d =
      device_from_json(device_json("", freqs_with(R"("harmonics": [{"h": 2, "amplitude": 0.05, "phase_rad": 0.5}],
                        "session_drift": [{"h": 2, "amplitude": 0.01, "phase_rad": -1.0}, {"h": 4, "amplitude": 0.002}])")));
  EXPECT_EQ(d.groups[0].drift_amplitude[2], 0.01);
  EXPECT_EQ(d.groups[0].drift_phase_rad[2], -1.0);
  EXPECT_EQ(d.groups[0].drift(4), std::complex<double>(0.002, 0.0));
  EXPECT_EQ(d.groups[1].drift(2), 0.0);
  const DeviceProfile back = device_from_json(device_to_json(d));
  for (std::size_t h = 0; h <= 32; ++h) {
    EXPECT_EQ(back.groups[0].drift_amplitude[h], d.groups[0].drift_amplitude[h]) << h;
    EXPECT_EQ(back.groups[0].drift_phase_rad[h], d.groups[0].drift_phase_rad[h]) << h;
  }
  // a profile without drift is written without the key (older readers stay able to read it)
  EXPECT_EQ(device_to_json(DeviceProfile::ideal_kinect2()).find("session_drift"), std::string::npos);
  EXPECT_NE(device_to_json(d).find("session_drift"), std::string::npos);
}

TEST(DeviceJson, RejectsBadSessionDrift) {
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("session_drift": {"h": 2})"))), "session_drift");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("session_drift": [{"h": 1, "amplitude": 0.1}])"))),
                  "h must be");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("session_drift": [{"h": 2, "amplitude": -0.1}])"))),
                  "session drift amplitudes");
  EXPECT_CONTAINS(device_error(device_json("", freqs_with(R"("session_drift": [{"h": 2, "gain": 0.1}])"))), "gain");
}

TEST(DeviceSession, MovesEachGroupAlongItsDrift) {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.groups[0].harmonic_amplitude[2] = 0.05;
  d.groups[0].harmonic_phase_rad[2] = 0.5;
  d.groups[0].drift_amplitude[2] = 0.01;
  d.groups[0].drift_phase_rad[2] = -1.0;
  d.groups[2].drift_amplitude[5] = 0.02;
  const DeviceProfile s = d.in_session({2.0, 7.0, -0.5});
  const std::complex<double> want = std::polar(0.05, 0.5) + 2.0 * std::polar(0.01, -1.0);
  EXPECT_NEAR(std::abs(s.groups[0].harmonic(2) - want), 0.0, 1e-15);
  EXPECT_EQ(s.groups[1].harmonic(2), 0.0);                                     // group 16 MHz has no drift
  EXPECT_NEAR(std::abs(s.groups[2].harmonic(5) - (-0.5 * 0.02)), 0.0, 1e-15);  // t < 0: the opposite way
  for (std::size_t g = 0; g < 3; ++g) {
    for (std::size_t h = 0; h <= 32; ++h) EXPECT_EQ(s.groups[g].drift_amplitude[h], 0.0) << g << " " << h;
    EXPECT_EQ(s.groups[g].harmonic(1), 1.0);
  }
  // state 0: the nominal waveform
  const DeviceProfile zero = d.in_session({0.0, 0.0, 0.0});
  EXPECT_NEAR(std::abs(zero.groups[0].harmonic(2) - d.groups[0].harmonic(2)), 0.0, 1e-16);
  // the original is untouched
  EXPECT_EQ(d.groups[0].drift_amplitude[2], 0.01);
}

TEST(DeviceSession, RejectsNonFiniteStatesAndAmplitudesAboveOne) {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.groups[1].drift_amplitude[2] = 0.5;
  EXPECT_THROW(d.in_session({0.0, std::nan(""), 0.0}), std::invalid_argument);
  EXPECT_THROW(d.in_session({0.0, INFINITY, 0.0}), std::invalid_argument);
  EXPECT_THROW(d.in_session({0.0, 3.0, 0.0}), std::invalid_argument);  // |G_2| = 1.5
  EXPECT_NO_THROW(d.in_session({0.0, 1.9, 0.0}));
}

// The seed is a uint64 and is written as a JSON integer, but read back
// through a double: seeds above 2^53 lose their low bits.
TEST(DeviceJson, SeedRoundTripsAllSixtyFourBits) {
  DeviceProfile d = rich_device();
  for (std::uint64_t seed : {std::uint64_t{0}, std::uint64_t{1} << 53, (std::uint64_t{1} << 53) + 1,
                             std::uint64_t{0xDEADBEEFCAFEF00Dull}, ~std::uint64_t{0}}) {
    d.pixel_phase.seed = seed;
    EXPECT_EQ(device_from_json(device_to_json(d)).pixel_phase.seed, seed) << std::hex << seed;
  }
}

// ---------------------------------------------------------------------------
// Material libraries
// ---------------------------------------------------------------------------

TEST(LibraryJson, ParsesMaterials) {
  const MaterialLibrary lib = library_from_json(library_json(
      kMat +
          R"(, {"name": "felt", "kind": "slab", "subsurface": 1, "tau_ps": 50, "thickness_mm": 2, "backing": 0.3, "notes": "x"})",
      R"("device": "kinect", "fit": {}, "notes": "n")"));
  ASSERT_EQ(lib.materials.size(), 2u);
  EXPECT_EQ(lib.find("cork").kind, ResponseKind::kExponential);
  EXPECT_EQ(lib.find("cork").tau_ps, 200.0);
  EXPECT_EQ(lib.find("felt").kind, ResponseKind::kSlab);
  EXPECT_EQ(lib.find("felt").albedo, Material{}.albedo);  // default
  EXPECT_THROW(lib.find("glass"), std::invalid_argument);
}

TEST(LibraryJson, RejectsUnknownKeys) {
  EXPECT_CONTAINS(library_error(library_json(kMat, R"("materialz": [])")), "materialz");
  EXPECT_CONTAINS(library_error(library_json(R"({"name": "a", "kind": "opaque", "colour": "red"})")), "colour");
  EXPECT_CONTAINS(library_error(library_json(R"({"name": "a", "kind": "opaque", "colour": "red"})")), "materials[0]");
}

TEST(LibraryJson, RejectsWrongVersionAndMissingName) {
  EXPECT_CONTAINS(library_error(R"({"name": "lib", "version": 3, "materials": [)" + kMat + "]}"), "version");
  EXPECT_CONTAINS(library_error(R"({"name": "lib", "materials": [)" + kMat + "]}"), "version");
  EXPECT_CONTAINS(library_error(R"({"version": 1, "materials": [)" + kMat + "]}"), "name");
  EXPECT_CONTAINS(library_error(library_json(R"({"kind": "opaque"})")), "name");
  EXPECT_CONTAINS(library_error(library_json(R"({"name": "a"})")), "kind");
}

TEST(LibraryJson, RejectsWrongTypesAndValues) {
  EXPECT_CONTAINS(library_error(library_json(R"({"name": "a", "kind": "opaque", "albedo": "0.5"})")), "albedo");
  EXPECT_CONTAINS(library_error(library_json(R"({"name": 3, "kind": "opaque"})")), "name");
  EXPECT_CONTAINS(library_error(library_json(R"({"name": "a", "kind": "glossy"})")), "kind");
  EXPECT_CONTAINS(library_error(library_json(R"({"name": "a", "kind": "opaque", "albedo": 10.5})")), "albedo");
  EXPECT_CONTAINS(library_error(library_json(R"({"name": "a", "kind": "exponential", "subsurface": 0.5})")), "tau_ps");
  EXPECT_CONTAINS(library_error(R"({"name": "lib", "version": 1, "materials": []})"), "materials");
  EXPECT_CONTAINS(library_error(R"({"name": "lib", "version": 1, "materials": {}})"), "materials");
  EXPECT_CONTAINS(library_error(R"({"name": "lib", "version": 1})"), "materials");
  EXPECT_CONTAINS(library_error(library_json(kMat + ", " + kMat)), "duplicate");
  EXPECT_FALSE(library_error("not json").empty());
}

TEST(LibraryJson, RoundTripIsExact) {
  MaterialLibrary lib;
  lib.name = "round";
  const ResponseKind kinds[] = {ResponseKind::kOpaque, ResponseKind::kExponential, ResponseKind::kGamma,
                                ResponseKind::kSlab};
  for (int i = 0; i < 4; ++i) {
    Material m;
    m.name = "m" + std::to_string(i);
    m.kind = kinds[i];
    m.albedo = 0.1 + 0.2 * i;
    m.subsurface = 1.0 / 3.0;
    m.tau_ps = 123.456 + i;
    m.gamma_k = 2.0 / 3.0;
    m.refractive_index = 1.0 + 1.0 / 7.0;
    m.thickness_mm = 0.1 + i;
    m.path_factor = 1.5;
    m.backing = 0.7;
    lib.materials.push_back(m);
  }
  const std::string text = library_to_json(lib);
  const MaterialLibrary back = library_from_json(text);
  EXPECT_EQ(back.name, lib.name);
  EXPECT_EQ(back.version, lib.version);
  ASSERT_EQ(back.materials.size(), lib.materials.size());
  for (std::size_t i = 0; i < lib.materials.size(); ++i) {
    const Material &a = lib.materials[i], &b = back.materials[i];
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.kind, b.kind);
    EXPECT_EQ(a.albedo, b.albedo);
    EXPECT_EQ(a.subsurface, b.subsurface);
    EXPECT_EQ(a.tau_ps, b.tau_ps);
    EXPECT_EQ(a.gamma_k, b.gamma_k);
    EXPECT_EQ(a.refractive_index, b.refractive_index);
    EXPECT_EQ(a.thickness_mm, b.thickness_mm);
    EXPECT_EQ(a.path_factor, b.path_factor);
    EXPECT_EQ(a.backing, b.backing);
  }
  EXPECT_EQ(library_to_json(back), text);
  const Material one = material_from_json(tofmat::sim::material_to_json(lib.materials[3]));
  EXPECT_EQ(one.backing, 0.7);
}

// ---------------------------------------------------------------------------
// Loading by name and by path
// ---------------------------------------------------------------------------

TEST(ProfileFiles, LoadByNameAndByPath) {
  tofmat_test::TempDir dir;
  std::filesystem::create_directories(dir.path() / "devices");
  std::filesystem::create_directories(dir.path() / "materials");
  std::ofstream(dir.path() / "devices" / "dev.json") << device_json();
  std::ofstream(dir.path() / "materials" / "lib.json") << library_json(kMat);
  std::ofstream(dir.path() / "broken.json") << device_json(R"("bogus": 1)");
  EXPECT_EQ(tofmat::sim::load_device("dev", dir.path()).name, "dev");
  EXPECT_EQ(tofmat::sim::load_device((dir.path() / "devices" / "dev.json").string(), "/nonexistent").name, "dev");
  EXPECT_EQ(tofmat::sim::load_library("lib", dir.path()).materials.size(), 1u);
  const std::string e =
      error_of<FormatError>([&] { tofmat::sim::load_device((dir.path() / "broken.json").string(), dir.path()); });
  EXPECT_CONTAINS(e, "broken.json");
  EXPECT_CONTAINS(e, "bogus");
  EXPECT_THROW(tofmat::sim::load_device("missing", dir.path()), tofmat::IoError);
}

}  // namespace
