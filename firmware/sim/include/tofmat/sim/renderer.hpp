// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Renders raw Kinect v2 frames: for every pixel and frequency group the three
// phase-step samples, as the camera delivers them (the 11-bit code's 16-bit
// values; 32767 where saturated), with shot and read noise, plus ground truth.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include "tofmat/sim/device.hpp"
#include "tofmat/sim/profile_io.hpp"
#include "tofmat/sim/scene.hpp"

namespace tofmat::sim {

// A pixel rectangle [x0, x1) x [y0, y1).
struct PixelRect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

// A rendered frame, or a region of one (origin x0, y0 in the full image).
struct Frame {
  int x0 = 0, y0 = 0;
  int width = 0, height = 0;
  std::vector<std::int16_t> raw;     // 9 x height x width: sub-image-major, rows top to bottom
  std::vector<float> range_mm;       // truth: distance along each pixel's ray, NaN where nothing
  std::vector<float> depth_mm;       // truth: z
  std::vector<std::int16_t> target;  // index into scene.targets, -1 background, -2 nothing
  std::vector<float> incidence_deg;  // truth: angle between ray and surface normal
};

// The AC part of one material's raw samples at one incidence per unit signal,
// tabulated over a period of the pixel phase for each group: ac[g][k * 3 + j]
// is step j at phase 2 pi k / kWaveformPoints (ac_per_unit). The taps, step
// gains and offsets are applied per pixel, because saturation is not linear in
// the signal. Linear interpolation between points errs by at most
// (2 pi / N)^2 / 8 * sum h^2 |G_h R_h| of the signal: for N = 4096 and the
// calibrated profile (16 MHz harmonics to h = 32) 8.8e-5 of it, 1.4 counts at
// the top of the range where the 11-bit code's steps are 64 counts.
inline constexpr int kWaveformPoints = 4096;
static_assert((kWaveformPoints & (kWaveformPoints - 1)) == 0, "the renderer wraps table positions by masking");
struct Waveform {
  std::array<std::vector<float>, 3> ac;
  double dc = 0.0;  // R(0, alpha): the received DC per unit signal
};

class Renderer {
 public:
  struct Vec3 {
    double x, y, z;
  };

  // threads: workers for a frame (0: one per hardware thread). The result does
  // not depend on it: noise is seeded per block of rows.
  Renderer(DeviceProfile device, MaterialLibrary library, int threads = 0);

  // Noise is seeded: the same seed gives the same frame. Safe to call from
  // several threads (the waveform cache is locked).
  Frame render(const Scene& scene, std::uint64_t seed, bool noise = true) const;
  // Only the pixels of `region`: what a stage capture or an ROI profile needs.
  Frame render_region(const Scene& scene, std::uint64_t seed, bool noise, const PixelRect& region) const;

  // Incidence is tabulated in steps of this many degrees: below 50 degrees the
  // Fresnel share changes the response by < 1e-3 per degree.
  static constexpr double kIncidenceStepDeg = 1.0;

  // The phase the P0 tables correct at each pixel (radians, group g), as the
  // simulated device reports it.
  const std::vector<float>& pixel_phase(int group) const { return pixel_phase_[static_cast<std::size_t>(group)]; }
  // The P0 correction the simulated device reports for each pixel:
  // -(pixel phase + the group's decode_offset_rad). Decoding with it gives the
  // phase plus eps_f, as the real camera's imperfect P0 tables do.
  std::vector<float> p0_table(int group) const;
  const DeviceProfile& device() const { return device_; }
  const MaterialLibrary& library() const { return library_; }

 private:
  DeviceProfile device_;
  MaterialLibrary library_;
  std::array<std::vector<float>, 3> pixel_phase_;
  std::vector<Vec3> rays_;  // unit ray per pixel
  int threads_ = 1;
  std::vector<float> saturation_;  // N(T) / T against |T| / W, for groups with a full well
  double linear_below_ = 0.0;      // |T| / W below which N(T) = T to 1e-7
  const Waveform& waveform(const Material& m, int incidence_step) const;
  mutable std::mutex cache_mutex_;
  mutable std::map<std::pair<const Material*, int>, std::unique_ptr<Waveform>> cache_;
};

}  // namespace tofmat::sim
