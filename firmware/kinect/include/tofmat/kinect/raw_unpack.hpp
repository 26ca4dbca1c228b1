// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The depth sub-image's packed 11-bit layout (kinect2-protocol.md 2.3) and its
// inverse. Rows: stored rows 0..211 are output rows 0..211, stored rows
// 212..423 are output rows 423 down to 212. Columns: output column x is slot
// 128 (x mod 4) + floor(x / 4) of its stored row, an 11-bit code at bit 11 p
// of the row read LSB-first from little-endian 16-bit words. Columns 0 and
// 511 always read code 0. Output orientation is the image orientation of the
// whole project (row 0 at the top), the one the P0 tables use.
//
// Two implementations. The definition (unpack_codes, unpack_raw_reference) is
// the layout read code by code as the protocol states it. The kernels
// (unpack_raw_rows, unpack_raw_region and the packet functions) give its
// values bit for bit, fast: a stored row is four runs of 128 slots, each run
// 176 bytes (byte aligned), each 8 slots 11 bytes, so group k of the four runs
// is output columns 32 k .. 32 k + 31 (slot 8 k + i of run r is column
// 4 (8 k + i) + r). A kernel extracts 8 or 16 codes at a time from a group's
// bytes, maps them to raw values and interleaves the four runs, a block of 32
// or 64 columns at a time. Kernels: scalar (64-bit loads and shifts, the
// device table), NEON on aarch64 and AVX2 on x86-64 CPUs that have it (the
// table computed from the code's bits; chosen as the fixed-point kernels are:
// FixedKernel::kBest, cpu_has_avx2). Every kernel writes exactly the pixels
// asked for, reads only the stored rows of those rows, and nothing beyond a
// row's 704 bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

#include "tofmat/core/fixed_kernel.hpp"
#include "tofmat/core/frame_decode.hpp"  // PixelRegion
#include "tofmat/kinect/constants.hpp"

namespace tofmat::kinect {

// The stored row that carries output row y.
int stored_row_of_output_row(int y);

// ---------------------------------------------------------------- definition

// 11-bit codes of one sub-image (kSubImageBytes) in output orientation:
// codes[y * 512 + x]. Reads exactly kSubImageBytes.
void unpack_codes(const std::uint8_t* sub_image, std::uint16_t* codes);

// Output rows [y0, y1) of one sub-image by the definition: the codes of
// unpack_codes mapped through the device's lookup table (raw_code_value).
// Writes raw[y * 512 + x] of those rows only. The reference the kernels are
// tested against and the benchmark's "before". Throws std::invalid_argument
// unless 0 <= y0 <= y1 <= 424.
void unpack_raw_reference(const std::uint8_t* sub_image, std::int16_t* raw, int y0 = 0, int y1 = kHeight);

// ---------------------------------------------------------------- the unpack

// Output rows [y0, y1) of one sub-image mapped through the device's lookup
// table to 16-bit raw values (32767 = saturated): raw[y * 512 + x] for those
// rows, every column; no other element of raw is written, and only the stored
// rows of y0..y1-1 are read. Throws std::invalid_argument unless
// 0 <= y0 <= y1 <= 424 (y0 == y1: nothing).
void unpack_raw_rows(const std::uint8_t* sub_image, std::int16_t* raw, int y0, int y1,
                     FixedKernel kernel = FixedKernel::kBest);

// Only the pixels of a rectangle [x0, x1) x [y0, y1) of one sub-image:
// raw[y * 512 + x] inside it, nothing else written. A region costs the blocks
// of 32 columns it touches (AVX2: 64), 2 or 3 of 16 per row for 48 columns. Throws
// std::invalid_argument unless 0 <= x0 <= x1 <= 512 and 0 <= y0 <= y1 <= 424.
void unpack_raw_region(const std::uint8_t* sub_image, std::int16_t* raw, const PixelRegion& region,
                       FixedKernel kernel = FixedKernel::kBest);

// All 424 rows: unpack_raw_rows(sub_image, raw, 0, 424).
void unpack_raw(const std::uint8_t* sub_image, std::int16_t* raw, FixedKernel kernel = FixedKernel::kBest);

// Output rows [y0, y1) of all nine used sub-images of a depth packet
// (kDepthPacketBytes, or at least 9 x kSubImageBytes) into the sub-image-major
// frame raw[9 * kPixels]: raw[s * kPixels + y * 512 + x] for s = 0..8 and
// those rows; every other element is left as it was. Throws
// std::invalid_argument unless 0 <= y0 <= y1 <= 424.
void unpack_depth_packet_rows(const std::uint8_t* packet, std::int16_t* raw, int y0, int y1,
                              FixedKernel kernel = FixedKernel::kBest);

// The same for the pixels of a rectangle only (what a consumer that decodes
// only a region, decode_region_fixed, reads): raw[s * kPixels + y * 512 + x]
// for s = 0..8 and (x, y) inside it. Throws std::invalid_argument unless
// 0 <= x0 <= x1 <= 512 and 0 <= y0 <= y1 <= 424.
void unpack_depth_packet_region(const std::uint8_t* packet, std::int16_t* raw, const PixelRegion& region,
                                FixedKernel kernel = FixedKernel::kBest);

// The whole frame: unpack_depth_packet_rows(packet, raw, 0, 424).
void unpack_depth_packet(const std::uint8_t* packet, std::int16_t* raw, FixedKernel kernel = FixedKernel::kBest);

// The kernel kBest runs on this machine: "neon", "avx2" or "scalar".
const char* best_unpack_kernel();

// The kernels themselves over a rectangle of one sub-image (no range check:
// 0 <= x0 <= x1 <= 512, 0 <= y0 <= y1 <= 424). Exposed for the bit-exactness
// tests.
void unpack_region_scalar(const std::uint8_t* sub_image, std::int16_t* raw, const PixelRegion& region);
#if defined(__aarch64__)
void unpack_region_neon(const std::uint8_t* sub_image, std::int16_t* raw, const PixelRegion& region);
#endif
#if defined(__x86_64__)
// Only on a CPU with AVX2 (cpu_has_avx2()).
void unpack_region_avx2(const std::uint8_t* sub_image, std::int16_t* raw, const PixelRegion& region);
#endif

// ---------------------------------------------------------------- device side

// The device side: pack output-orientation codes (low 11 bits used) into a
// sub-image (kSubImageBytes, fully written). Columns 0 and 511 are packed as
// given; the reader ignores them.
void pack_codes(const std::uint16_t* codes, std::uint8_t* sub_image);

// The layout's numbers and the row walk the kernels share (2.3: 704-byte rows
// of 512 slots).
namespace unpack_detail {
inline constexpr std::size_t kRunBytes = 176;   // 128 slots (one column residue x mod 4) x 11 bits
inline constexpr std::size_t kGroupBytes = 11;  // 8 slots x 11 bits
inline constexpr std::size_t kGroupsPerRun = 16;
inline constexpr int kBlockColumns = 32;  // group k of the four runs: columns 32 k ..

// Columns [x0, x1) of one output row, `Width` columns (a multiple of 32) at a
// time: block(b, dst) writes columns Width b .. Width b + Width - 1 to dst.
// Blocks wholly inside go straight to the row; a block the range cuts goes
// through a buffer, of which only the range's part is copied. Columns 0 and
// 511 read 0 (2.3) whatever the block wrote.
template <int Width, class Block>
inline void unpack_row_columns(std::int16_t* out, int x0, int x1, Block&& block) {
  if (x0 >= x1) return;
  for (int b = x0 / Width; b * Width < x1; ++b) {
    const int first = b * Width;
    if (first >= x0 && first + Width <= x1) {
      block(b, out + first);
    } else {
      alignas(32) std::int16_t buffer[Width];
      block(b, buffer);
      const int from = first > x0 ? first : x0, to = first + Width < x1 ? first + Width : x1;
      std::memcpy(out + from, buffer + (from - first), static_cast<std::size_t>(to - from) * sizeof(std::int16_t));
    }
  }
  if (x0 == 0) out[0] = 0;
  if (x1 == kWidth) out[kWidth - 1] = 0;
}
}  // namespace unpack_detail

}  // namespace tofmat::kinect
