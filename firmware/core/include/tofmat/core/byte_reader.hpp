// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Bounds-checked little-endian reading of untrusted bytes. Every read checks
// the remaining length first, so a parser built on it cannot read past the end
// whatever the input says about its own lengths.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "tofmat/core/error.hpp"

namespace tofmat {

class ByteReader {
 public:
  ByteReader(const std::uint8_t* data, std::size_t size, std::string what)
      : data_(data), size_(size), what_(std::move(what)) {}

  std::size_t offset() const { return pos_; }
  std::size_t remaining() const { return size_ - pos_; }

  // Throws FormatError naming `field` when fewer than n bytes remain.
  const std::uint8_t* take(std::size_t n, std::string_view field) {
    if (n > remaining()) {
      throw FormatError(what_ + ": truncated while reading " + std::string(field) + " at byte " + std::to_string(pos_) +
                        " (need " + std::to_string(n) + ", have " + std::to_string(remaining()) + ")");
    }
    const std::uint8_t* p = data_ + pos_;
    pos_ += n;
    return p;
  }

  std::uint8_t u8(std::string_view field) { return *take(1, field); }
  std::uint16_t u16(std::string_view field) { return static_cast<std::uint16_t>(le(take(2, field), 2)); }
  std::uint32_t u32(std::string_view field) { return static_cast<std::uint32_t>(le(take(4, field), 4)); }
  std::uint64_t u64(std::string_view field) { return le(take(8, field), 8); }
  float f32(std::string_view field) {
    const std::uint32_t bits = u32(field);
    float v;
    std::memcpy(&v, &bits, sizeof v);
    return v;
  }
  double f64(std::string_view field) {
    const std::uint64_t bits = u64(field);
    double v;
    std::memcpy(&v, &bits, sizeof v);
    return v;
  }

 private:
  static std::uint64_t le(const std::uint8_t* p, int n) {
    std::uint64_t v = 0;
    for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
    return v;
  }

  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  std::string what_;
};

}  // namespace tofmat
