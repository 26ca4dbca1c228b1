// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// What travels from a source (USB/event thread) to the processing thread: one
// depth frame as the nine raw phase-step images, the device's P0 corrections
// it must be decoded with, and, for the simulated camera, the ground truth.
#pragma once
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/frame_decode.hpp"
#include "tofmat/kinect/command.hpp"

namespace tofmat::daemon {

inline constexpr int kWidth = 512;
inline constexpr int kHeight = 424;
inline constexpr std::size_t kPixels = static_cast<std::size_t>(kWidth) * kHeight;

inline bool region_empty(const PixelRegion& r) { return r.x1 <= r.x0 || r.y1 <= r.y0; }
// True when `outer` holds every pixel of `inner`.
inline bool region_covers(const PixelRegion& outer, const PixelRegion& inner) {
  return region_empty(inner) ||
         (outer.x0 <= inner.x0 && outer.y0 <= inner.y0 && inner.x1 <= outer.x1 && inner.y1 <= outer.y1);
}

// What the device told at its start, shared by its frames (neither changes
// while the camera streams): the decode's per-pixel corrections built from
// its P0 tables, and its depth camera's intrinsics (the depth-parameters
// page; none from a recording made before recordings kept them).
struct Calibration {
  explicit Calibration(const std::vector<float>& p0, std::optional<kinect::DepthParams> depth_intrinsics = std::nullopt)
      : p0_rad(p0), float_tables(p0, kPixels), fixed_tables(p0, kPixels), intrinsics(depth_intrinsics) {}
  std::vector<float> p0_rad;  // 3 x kPixels
  DecodeTables float_tables;
  FixedDecodeTables fixed_tables;
  std::optional<kinect::DepthParams> intrinsics;
};

// Ground truth of a simulated frame: per pixel, the index into `materials` of
// the target seen there (-1: none), and the true depth.
struct FrameTruth {
  std::vector<std::string> materials;
  std::vector<std::int16_t> target;  // kPixels
  std::vector<float> depth_mm;       // kPixels, NaN where nothing
};

struct RawFrame {
  std::uint64_t sequence = 0;
  std::uint64_t arrival_ns = 0;   // CLOCK_MONOTONIC when the last packet arrived
  std::vector<std::int16_t> raw;  // 9 x kPixels, sub-image-major (or empty: nothing unpacked)
  // The pixels of `raw` that hold this frame's samples: a camera source
  // unpacks only what the profile reads (Pipeline::wanted_region); the rest
  // of a recycled buffer is stale. Empty (x0 == x1) when nothing was unpacked.
  PixelRegion region{0, 0, kWidth, kHeight};
  std::shared_ptr<const Calibration> calibration;
  std::shared_ptr<const FrameTruth> truth;  // null for a real camera
  bool simulated = false;                   // rendered by the simulator (or a replay of such frames)
};

}  // namespace tofmat::daemon
