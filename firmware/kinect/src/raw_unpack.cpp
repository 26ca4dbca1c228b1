#include "tofmat/kinect/raw_unpack.hpp"

#include <array>
#include <cstring>

#include "tofmat/core/raw_lut.hpp"
#include "tofmat/kinect/constants.hpp"

namespace tofmat::kinect {
namespace {

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

}  // namespace

int stored_row_of_output_row(int y) { return y < kHeight / 2 ? y : kHeight / 2 + (kHeight - 1 - y); }

void unpack_codes(const std::uint8_t* sub_image, std::uint16_t* codes) {
  for (int y = 0; y < kHeight; ++y) {
    const std::uint8_t* row = sub_image + static_cast<std::size_t>(stored_row_of_output_row(y)) * kRowBytes;
    std::uint16_t* out = codes + static_cast<std::size_t>(y) * kWidth;
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
}

void unpack_raw(const std::uint8_t* sub_image, std::int16_t* raw) {
  static thread_local std::array<std::uint16_t, kPixels> codes;
  unpack_codes(sub_image, codes.data());
  const auto& t = lut();
  for (std::size_t i = 0; i < kPixels; ++i) raw[i] = t[codes[i]];
}

void unpack_depth_packet(const std::uint8_t* packet, std::int16_t* raw) {
  for (int s = 0; s < kUsedSubImages; ++s) {
    unpack_raw(packet + static_cast<std::size_t>(s) * kSubImageBytes, raw + static_cast<std::size_t>(s) * kPixels);
  }
}

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
