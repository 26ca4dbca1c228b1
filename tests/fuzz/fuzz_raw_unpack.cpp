// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: the 11-bit unpack of a depth packet (kinect2-protocol.md
// 2.3, 2.4; firmware/kinect/raw_unpack.hpp) on arbitrary bytes. The dispatched
// packet unpack (kBest: AVX2 or NEON where the machine has it) and the scalar
// kernel must give the definition's values bit for bit over a region (rows and
// columns) the input picks, and write nothing outside it.
//
// Input: bytes 0-1 (little-endian) pick y0 (mod 425), bytes 2-3 the number of
// rows (mod 425 - y0), bytes 4-5 x0 (mod 513), bytes 6-7 the number of
// columns (mod 513 - x0; an even byte 8 makes the region whole rows), byte 8
// also the sub-image checked against the definition (byte 8 / 2 mod 9); the
// rest is the packet's content, repeated over every stored row the region
// reads (sub-image s starts 7 s bytes further into it, so the nine differ).
// The packet unpack runs on all nine sub-images (none may write outside the
// region); the definition and the scalar kernel on the one checked:
// in this build (coverage, comparison tracing and a pointer check on every
// access) each costs ten to twenty times the vector kernel, and all nine
// sub-images run the same code at other offsets. The packet is exactly nine sub-images long, so the
// sanitizers see any read past its end (stored row 423 of sub-image 8, output
// row 212, ends there).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "tofmat/core/fixed_kernel.hpp"
#include "tofmat/core/frame_decode.hpp"
#include "tofmat/kinect/constants.hpp"
#include "tofmat/kinect/raw_unpack.hpp"

namespace {

using namespace tofmat::kinect;

constexpr std::size_t kFrame = static_cast<std::size_t>(kUsedSubImages) * kPixels;
constexpr std::int16_t kUnwritten = 0x5A5A;  // no code's value (within +-16320, or 32767)

// The elements of frame f (one sub-image) outside rows [y0, y1) still hold
// kUnwritten, and within those rows those outside columns [x0, x1).
bool untouched_outside(const std::int16_t* f, const std::int16_t* blank, const tofmat::PixelRegion& g) {
  const std::size_t before = static_cast<std::size_t>(g.y0) * kWidth, after = static_cast<std::size_t>(g.y1) * kWidth;
  if (std::memcmp(f, blank, before * sizeof(std::int16_t)) != 0 ||
      std::memcmp(f + after, blank, (kPixels - after) * sizeof(std::int16_t)) != 0) {
    return false;
  }
  for (int y = g.y0; y < g.y1; ++y) {
    const std::int16_t* row = f + static_cast<std::size_t>(y) * kWidth;
    if (std::memcmp(row, blank, static_cast<std::size_t>(g.x0) * sizeof(std::int16_t)) != 0 ||
        std::memcmp(row + g.x1, blank, static_cast<std::size_t>(kWidth - g.x1) * sizeof(std::int16_t)) != 0) {
      return false;
    }
  }
  return true;
}

// The region's pixels of a and b are the same.
bool region_equal(const std::int16_t* a, const std::int16_t* b, const tofmat::PixelRegion& g) {
  for (int y = g.y0; y < g.y1; ++y) {
    const std::size_t at = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(g.x0);
    if (std::memcmp(a + at, b + at, static_cast<std::size_t>(g.x1 - g.x0) * sizeof(std::int16_t)) != 0) return false;
  }
  return true;
}

void blank_region(std::int16_t* f, const std::int16_t* blank, const tofmat::PixelRegion& g) {
  for (int y = g.y0; y < g.y1; ++y) {
    const std::size_t at = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(g.x0);
    std::memcpy(f + at, blank, static_cast<std::size_t>(g.x1 - g.x0) * sizeof(std::int16_t));
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // Static buffers (reused: a frame is 3.9 MB); the outputs start all kUnwritten.
  static std::vector<std::uint8_t> packet(static_cast<std::size_t>(kUsedSubImages) * kSubImageBytes);
  static const std::vector<std::int16_t> blank(kPixels, kUnwritten);
  static std::vector<std::int16_t> best(kFrame, kUnwritten), scalar(kPixels, kUnwritten), want(kPixels, kUnwritten);
  if (size < 9) return 0;
  tofmat::PixelRegion g;
  g.y0 = (data[0] | data[1] << 8) % (kHeight + 1);
  g.y1 = g.y0 + (data[2] | data[3] << 8) % (kHeight + 1 - g.y0);
  g.x0 = (data[4] | data[5] << 8) % (kWidth + 1);
  g.x1 = g.x0 + (data[6] | data[7] << 8) % (kWidth + 1 - g.x0);
  const bool whole_rows = data[8] % 2 == 0;
  if (whole_rows) {
    g.x0 = 0;
    g.x1 = kWidth;
  }
  const int checked = data[8] / 2 % kUsedSubImages;
  const std::uint8_t* content = data + 9;
  const std::size_t n = size - 9;

  // The content repeated to one row plus one period: any stored row's bytes
  // are then one contiguous copy from the right phase.
  static std::vector<std::uint8_t> tiled;
  tiled.assign(kRowBytes + n, 0);
  for (std::size_t j = 0; n != 0 && j < tiled.size(); j += n) {
    std::memcpy(tiled.data() + j, content, std::min(n, tiled.size() - j));
  }
  for (int s = 0; s < kUsedSubImages; ++s) {
    std::uint8_t* sub = packet.data() + static_cast<std::size_t>(s) * kSubImageBytes;
    for (int y = g.y0; y < g.y1; ++y) {
      const auto r = static_cast<std::size_t>(stored_row_of_output_row(y));
      const std::size_t phase = n == 0 ? 0 : (7 * static_cast<std::size_t>(s) + r * kRowBytes) % n;
      std::memcpy(sub + r * kRowBytes, tiled.data() + phase, kRowBytes);
    }
  }

  const std::uint8_t* sub = packet.data() + static_cast<std::size_t>(checked) * kSubImageBytes;
  if (whole_rows) {  // the rows API
    unpack_depth_packet_rows(packet.data(), best.data(), g.y0, g.y1);
    unpack_raw_rows(sub, scalar.data(), g.y0, g.y1, tofmat::FixedKernel::kScalar);
  } else {
    unpack_depth_packet_region(packet.data(), best.data(), g);
    unpack_raw_region(sub, scalar.data(), g, tofmat::FixedKernel::kScalar);
  }
  unpack_raw_reference(sub, want.data(), g.y0, g.y1);  // whole rows: the region is compared

  const std::int16_t* best_checked = best.data() + static_cast<std::size_t>(checked) * kPixels;
  if (!region_equal(best_checked, want.data(), g) || !region_equal(scalar.data(), want.data(), g)) __builtin_trap();
  if (!untouched_outside(scalar.data(), blank.data(), g)) __builtin_trap();
  for (int s = 0; s < kUsedSubImages; ++s) {
    std::int16_t* f = best.data() + static_cast<std::size_t>(s) * kPixels;
    if (!untouched_outside(f, blank.data(), g)) __builtin_trap();
    blank_region(f, blank.data(), g);  // back to kUnwritten for the next input
  }
  blank_region(scalar.data(), blank.data(), g);
  return 0;
}
