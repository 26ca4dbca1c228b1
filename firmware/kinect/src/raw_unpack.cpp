// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The 11-bit unpack of the depth sub-images (kinect2-protocol.md 2.3, 2.4):
// the definition (code by code, as the protocol states the layout), the
// scalar kernel, the dispatch to the NEON / AVX2 kernels
// (raw_unpack_neon.cpp, raw_unpack_avx2.cpp), and the device-side pack.
#include "tofmat/kinect/raw_unpack.hpp"

#include <array>
#include <cstring>
#include <stdexcept>
#include <string>

#include "tofmat/core/raw_lut.hpp"
#include "tofmat/kinect/constants.hpp"

namespace tofmat::kinect {
namespace {

using namespace unpack_detail;

constexpr std::size_t kWordsPerRow = kRowBytes / 2;  // 352

// Slot of output column x within a stored row.
constexpr int slot_of_column(int x) { return 128 * (x % 4) + x / 4; }

std::uint16_t word_at(const std::uint8_t* row, std::size_t w) {
  // The last slot's code ends exactly at the row's last bit: there is no
  // next word to read, and none is read (the row is the bound, not the packet).
  if (w >= kWordsPerRow) return 0;
  return static_cast<std::uint16_t>(row[2 * w] | (row[2 * w + 1] << 8));
}

const std::array<std::int16_t, 2048>& lut() {
  static const std::array<std::int16_t, 2048> table = [] {
    std::array<std::int16_t, 2048> t{};
    for (std::uint16_t c = 0; c < 2048; ++c) t[c] = raw_code_value(c);
    return t;
  }();
  return table;
}

const std::uint8_t* stored_row(const std::uint8_t* sub_image, int y) {
  return sub_image + static_cast<std::size_t>(stored_row_of_output_row(y)) * kRowBytes;
}

// The definition of one row: every column's code read from two 16-bit words.
void reference_row_codes(const std::uint8_t* row, std::uint16_t* out) {
  out[0] = 0;
  out[kWidth - 1] = 0;
  for (int x = 1; x < kWidth - 1; ++x) {
    const auto bit = static_cast<std::size_t>(11 * slot_of_column(x));
    const std::size_t w = bit / 16;
    const unsigned shift = bit % 16;
    const std::uint32_t two = word_at(row, w) | (static_cast<std::uint32_t>(word_at(row, w + 1)) << 16);
    out[x] = static_cast<std::uint16_t>((two >> shift) & 0x7FFu);
  }
}

void check_rows(int y0, int y1) {
  if (y0 < 0 || y1 > kHeight || y0 > y1) {
    throw std::invalid_argument("unpack: rows [" + std::to_string(y0) + ", " + std::to_string(y1) +
                                ") are not within [0, 424)");
  }
}

void check_region(const PixelRegion& r) {
  check_rows(r.y0, r.y1);
  if (r.x0 < 0 || r.x1 > kWidth || r.x0 > r.x1) {
    throw std::invalid_argument("unpack: columns [" + std::to_string(r.x0) + ", " + std::to_string(r.x1) +
                                ") are not within [0, 512)");
  }
}

// Eight little-endian bytes as one number (the bit stream is LSB-first).
inline std::uint64_t load_le64(const std::uint8_t* p) {
  std::uint64_t v;
  std::memcpy(&v, p, sizeof v);
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  v = __builtin_bswap64(v);
#endif
  return v;
}

// Columns 32 b .. 32 b + 31 of one output row from its stored row: group b
// (8 slots) of each of the four runs, slot 8 b + i of run r being column
// 4 (8 b + i) + r. A group is 11 bytes (88 bits): slots 0..4 (bits 0..54)
// lie in the 8 bytes at the group's start, slots 5..7 (bits 55..87) in the 8
// bytes from its byte 3 (bits 24..87), so the two loads read the group's 11
// bytes and nothing after it, and every code is one shift and one mask with
// no bound to test (the definition's "no word past the row" holds by
// construction, for the row's last group too).
inline void unpack_block_scalar(const std::uint8_t* row, int b, std::int16_t* dst, const std::int16_t* table) {
  const std::uint8_t* g = row + static_cast<std::size_t>(b) * kGroupBytes;
  for (std::size_t r = 0; r < 4; ++r, g += kRunBytes) {
    const std::uint64_t lo = load_le64(g), hi = load_le64(g + 3);
    std::int16_t* o = dst + r;
    o[0] = table[lo & 0x7FF];
    o[4] = table[(lo >> 11) & 0x7FF];
    o[8] = table[(lo >> 22) & 0x7FF];
    o[12] = table[(lo >> 33) & 0x7FF];
    o[16] = table[(lo >> 44) & 0x7FF];
    o[20] = table[(hi >> 31) & 0x7FF];  // bit 55 of the group
    o[24] = table[(hi >> 42) & 0x7FF];  // bit 66
    o[28] = table[hi >> 53];            // bit 77: the group's last 11 bits
  }
}

}  // namespace

int stored_row_of_output_row(int y) { return y < kHeight / 2 ? y : kHeight / 2 + (kHeight - 1 - y); }

void unpack_codes(const std::uint8_t* sub_image, std::uint16_t* codes) {
  for (int y = 0; y < kHeight; ++y) {
    reference_row_codes(stored_row(sub_image, y), codes + static_cast<std::size_t>(y) * kWidth);
  }
}

void unpack_raw_reference(const std::uint8_t* sub_image, std::int16_t* raw, int y0, int y1) {
  check_rows(y0, y1);
  const auto& t = lut();
  std::array<std::uint16_t, kWidth> codes;
  for (int y = y0; y < y1; ++y) {
    reference_row_codes(stored_row(sub_image, y), codes.data());
    std::int16_t* out = raw + static_cast<std::size_t>(y) * kWidth;
    for (std::size_t x = 0; x < codes.size(); ++x) out[x] = t[codes[x]];
  }
}

void unpack_region_scalar(const std::uint8_t* sub_image, std::int16_t* raw, const PixelRegion& region) {
  const std::int16_t* table = lut().data();
  for (int y = region.y0; y < region.y1; ++y) {
    const std::uint8_t* row = stored_row(sub_image, y);
    unpack_row_columns<kBlockColumns>(raw + static_cast<std::size_t>(y) * kWidth, region.x0, region.x1,
                                      [&](int b, std::int16_t* dst) { unpack_block_scalar(row, b, dst, table); });
  }
}

void unpack_raw_region(const std::uint8_t* sub_image, std::int16_t* raw, const PixelRegion& region,
                       FixedKernel kernel) {
  check_region(region);
#if defined(__aarch64__)
  if (kernel == FixedKernel::kBest) return unpack_region_neon(sub_image, raw, region);
#elif defined(__x86_64__)
  if (kernel == FixedKernel::kBest && cpu_has_avx2()) return unpack_region_avx2(sub_image, raw, region);
#endif
  (void)kernel;
  unpack_region_scalar(sub_image, raw, region);
}

void unpack_raw_rows(const std::uint8_t* sub_image, std::int16_t* raw, int y0, int y1, FixedKernel kernel) {
  unpack_raw_region(sub_image, raw, PixelRegion{0, y0, kWidth, y1}, kernel);
}

void unpack_raw(const std::uint8_t* sub_image, std::int16_t* raw, FixedKernel kernel) {
  unpack_raw_rows(sub_image, raw, 0, kHeight, kernel);
}

void unpack_depth_packet_region(const std::uint8_t* packet, std::int16_t* raw, const PixelRegion& region,
                                FixedKernel kernel) {
  check_region(region);
  for (int s = 0; s < kUsedSubImages; ++s) {
    unpack_raw_region(packet + static_cast<std::size_t>(s) * kSubImageBytes,
                      raw + static_cast<std::size_t>(s) * kPixels, region, kernel);
  }
}

void unpack_depth_packet_rows(const std::uint8_t* packet, std::int16_t* raw, int y0, int y1, FixedKernel kernel) {
  unpack_depth_packet_region(packet, raw, PixelRegion{0, y0, kWidth, y1}, kernel);
}

void unpack_depth_packet(const std::uint8_t* packet, std::int16_t* raw, FixedKernel kernel) {
  unpack_depth_packet_rows(packet, raw, 0, kHeight, kernel);
}

// The unpack dispatches FixedKernel::kBest as the core's kernels do.
const char* best_unpack_kernel() { return best_pixel_kernel(); }

void pack_codes(const std::uint16_t* codes, std::uint8_t* sub_image) {
  std::memset(sub_image, 0, kSubImageBytes);
  for (int y = 0; y < kHeight; ++y) {
    std::uint8_t* row = sub_image + static_cast<std::size_t>(stored_row_of_output_row(y)) * kRowBytes;
    const std::uint16_t* in = codes + static_cast<std::size_t>(y) * kWidth;
    for (int x = 0; x < kWidth; ++x) {
      const auto bit = static_cast<std::size_t>(11 * slot_of_column(x));
      const std::uint32_t v = static_cast<std::uint32_t>(in[x] & 0x7FFu) << (bit % 8);
      // 11 bits at any bit offset span at most 3 bytes, all inside the row.
      for (std::size_t k = 0; k < 3 && bit / 8 + k < kRowBytes; ++k) {
        row[bit / 8 + k] = static_cast<std::uint8_t>(row[bit / 8 + k] | ((v >> (8 * k)) & 0xFFu));
      }
    }
  }
}

}  // namespace tofmat::kinect
