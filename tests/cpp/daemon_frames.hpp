// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Inputs for the daemon's unit tests (test_region_matcher, test_profiles,
// test_pipeline): the real database as the exemplar table, and raw 512 x 424
// frames in which rectangles of the image show a material. The frames come from
// the phasor model of synthetic_raw.hpp (samples B + A cos(theta + phi_j)), with
// each group's depth chosen so that the decode's Eq. (10) features equal a
// material's table curve at the bin of the pixel's combined depth: the right
// answer is then known without running any daemon code. Pixels outside every
// rectangle are all-zero samples, which the decode flags dark (nothing there).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "synthetic_raw.hpp"
#include "test_util.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/daemon/frame.hpp"
#include "tofmat/daemon/profile.hpp"

namespace tofmat_test {

using tofmat::daemon::kHeight;
using tofmat::daemon::kPixels;
using tofmat::daemon::kWidth;

// The real database folder as tofmatd loads it (daemon.cpp: linspace(600,
// 1200, 200) bins, the Kinect v2 rows). Loaded once per test program; its
// absence fails every test that needs it (never a skip, see test_util.hpp).
inline std::shared_ptr<const tofmat::ExemplarTable> real_table() {
  static const auto table = [] {
    try {
      return std::make_shared<const tofmat::ExemplarTable>(
          tofmat::ExemplarTable::from_npy_dir(db_dir(), tofmat::kDatabaseBinStartMm, tofmat::kDatabaseBinStopMm));
    } catch (const std::exception& e) {
      throw std::runtime_error("the real Kinect v2 database at '" + db_dir().string() +
                               "' (CMake cache variable TOFMAT_DB_DIR) does not load: " + e.what());
    }
  }();
  return table;
}

// P0 corrections that differ from pixel to pixel and group to group, as a real
// camera's do, so that a decode that ignored or misplaced them would be seen.
inline std::vector<float> varying_p0() {
  // A sum of a column term and a row term (each computed once per column or row).
  std::vector<float> p0(3 * kPixels);
  const double mean[3] = {0.4, -0.3, 1.1};
  std::vector<double> column(kWidth), row(kHeight);
  for (std::size_t g = 0; g < 3; ++g) {
    const double phase = static_cast<double>(g);
    for (int x = 0; x < kWidth; ++x)
      column[static_cast<std::size_t>(x)] = mean[g] + 0.25 * std::sin(0.013 * x + 0.7 * phase);
    for (int y = 0; y < kHeight; ++y) row[static_cast<std::size_t>(y)] = 0.15 * std::cos(0.021 * y - 0.3 * phase);
    for (std::size_t y = 0; y < static_cast<std::size_t>(kHeight); ++y)
      for (std::size_t x = 0; x < static_cast<std::size_t>(kWidth); ++x)
        p0[g * kPixels + y * kWidth + x] = static_cast<float>(column[x] + row[y]);
  }
  return p0;
}

// Built once: its decode tables cost as much as a few frames.
inline std::shared_ptr<const tofmat::daemon::Calibration> test_calibration() {
  static const auto calibration = std::make_shared<const tofmat::daemon::Calibration>(varying_p0());
  return calibration;
}

// The wrapped depths a pixel shows at each frequency, group order 80, 16, 120 MHz.
struct GroupDepths {
  double mm[3];
};

// Depths whose decode gives combined depth `combined_mm` and the features
// f16 = d16 - d120 and f80 = d80 - d120: with D16 = D120 + f16 and D80 = D120 +
// f80, the combined depth (80 D80 + 16 D16 + 120 D120) / 216 (decode.hpp) is
// D120 + (80 f80 + 16 f16) / 216. Valid while every depth stays inside its own
// unambiguous range (true for the database's 600..1200 mm and its features).
inline GroupDepths depths_with_features(double combined_mm, double f16, double f80) {
  const double d120 = combined_mm - (80.0 * f80 + 16.0 * f16) / 216.0;
  return {{d120 + f80, d120 + f16, d120}};
}

// What `material` looks like at the centre of `bin` of the table.
inline GroupDepths material_at_bin(const tofmat::ExemplarTable& table, const std::string& material, std::uint32_t bin) {
  const auto m = table.index_of(material);
  if (m < 0) throw std::logic_error("test setup: no material " + material);
  const float* v = table.material_values(static_cast<std::size_t>(m));
  const float f16 = v[bin], f80 = v[table.n_bins() + bin];
  if (!std::isfinite(f16) || !std::isfinite(f80))
    throw std::logic_error("test setup: " + material + " has no value at bin " + std::to_string(bin));
  return depths_with_features(table.bins().centre_mm(bin), f16, f80);
}

// A flat object (the same depths over a pixel rectangle).
struct Patch {
  tofmat::PixelRegion region;
  GroupDepths depths;
  double amplitude = 800.0;  // counts: a real target at a metre is hundreds
  double offset = 300.0;
};

// cos and sin of the phase steps 0, 120 and 240 degrees.
inline constexpr double kStepCos[3] = {1.0, -0.5, -0.5};
inline constexpr double kStepSin[3] = {0.0, 0.86602540378443864676, -0.86602540378443864676};

// Draws the patches (later ones cover earlier ones) into a frame's raw
// samples, with Gaussian sample noise of `noise_counts` inside the patches
// (seeded by the frame's sequence number: the same call draws the same frame).
inline void paint(tofmat::daemon::RawFrame& f, const std::vector<Patch>& patches, double noise_counts) {
  std::mt19937_64 rng(f.sequence * 7919u + 17u);
  std::normal_distribution<double> noise(0.0, noise_counts > 0.0 ? noise_counts : 1.0);
  const std::vector<float>& p0 = f.calibration->p0_rad;
  for (const Patch& p : patches)
    for (int y = p.region.y0; y < p.region.y1; ++y)
      for (int x = p.region.x0; x < p.region.x1; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x);
        for (std::size_t g = 0; g < 3; ++g) {
          const double theta =
              2.0 * tofmat::kPi * p.depths.mm[g] / kGroupRangeMm[g] + static_cast<double>(p0[g * kPixels + i]);
          const double c = std::cos(theta), s = std::sin(theta);
          for (std::size_t j = 0; j < 3; ++j) {
            // cos(theta + phi_j) by the angle sum: two calls per group, not three.
            const double wave = c * kStepCos[j] - s * kStepSin[j];
            const double n = noise_counts > 0.0 ? noise(rng) : 0.0;
            f.raw[(3 * g + j) * kPixels + i] = raw_sample(p.offset + p.amplitude * wave + n);
          }
        }
      }
}

// When frame `sequence` arrives: 30 frames/s after the first second.
inline std::uint64_t arrival_of(std::uint64_t sequence) { return 1'000'000'000ull + sequence * 33'000'000ull; }

// A frame of its own (what a source hands to the pipeline) showing the patches on nothing.
inline tofmat::daemon::RawFrame make_frame(std::uint64_t sequence, const std::vector<Patch>& patches,
                                           double noise_counts = 0.0,
                                           std::shared_ptr<const tofmat::daemon::Calibration> calibration = {}) {
  static const std::vector<std::int16_t> nothing(9 * kPixels, 0);
  tofmat::daemon::RawFrame f;
  f.sequence = sequence;
  f.arrival_ns = arrival_of(sequence);
  f.calibration = calibration ? std::move(calibration) : test_calibration();
  f.raw = nothing;  // (a copy is a memmove; filling 2 M samples one by one is slow in a Debug build)
  paint(f, patches, noise_counts);
  return f;
}

// Frames for code that only reads them (a profile's process()), drawn into one
// buffer: only the previous frame's patches are cleared, so a long sweep does
// not allocate and clear 4 MB a frame (slow under AddressSanitizer).
class FrameMaker {
 public:
  const tofmat::daemon::RawFrame& draw(std::uint64_t sequence, const std::vector<Patch>& patches,
                                       double noise_counts = 0.0) {
    if (frame_.raw.empty()) frame_ = make_frame(sequence, {});
    for (const Patch& p : drawn_)
      for (std::size_t s = 0; s < 9; ++s)
        for (int y = p.region.y0; y < p.region.y1; ++y) {
          auto* row = frame_.raw.data() + s * kPixels + static_cast<std::size_t>(y) * kWidth;
          std::fill(row + p.region.x0, row + p.region.x1, std::int16_t{0});
        }
    frame_.sequence = sequence;
    frame_.arrival_ns = arrival_of(sequence);
    paint(frame_, patches, noise_counts);
    drawn_ = patches;
    return frame_;
  }

 private:
  tofmat::daemon::RawFrame frame_;
  std::vector<Patch> drawn_;
};

// The centred 48 x 48 ROI of the default ProfileConfig.
inline constexpr tofmat::PixelRegion kCentreRoi{232, 188, 280, 236};

// A target filling the default ROI (and a margin of 4 pixels around it), showing `material` at `bin`.
inline Patch target_in_roi(const std::string& material, std::uint32_t bin) {
  return Patch{{228, 184, 284, 240}, material_at_bin(*real_table(), material, bin)};
}

// What a profile emitted, on one thread (the profile tests call process()
// directly). Depth events are asked for only of the kinds in `depth_kinds`.
struct EventLog {
  std::vector<tofmat::protocol::LabelEvent> labels;
  std::vector<tofmat::protocol::LabelMapEvent> maps;
  std::vector<tofmat::protocol::DepthEvent> depths;
  std::set<std::string> depth_kinds;

  tofmat::daemon::Emitter emitter() {
    tofmat::daemon::Emitter e;
    e.label = [this](const tofmat::protocol::LabelEvent& l) { labels.push_back(l); };
    e.label_map = [this](const tofmat::protocol::LabelMapEvent& m) { maps.push_back(m); };
    e.wants_depth = [this](const std::string& kind) { return depth_kinds.count(kind) > 0; };
    e.depth = [this](const tofmat::protocol::DepthEvent& d) { depths.push_back(d); };
    return e;
  }
  void clear() {
    labels.clear();
    maps.clear();
    depths.clear();
  }
};

}  // namespace tofmat_test
