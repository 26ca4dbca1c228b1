// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: parse_npy on arbitrary bytes. The only acceptable outcomes
// are a self-consistent array or tofmat::FormatError; any other exception
// escapes to libFuzzer (a finding), as do crashes and sanitizer reports.
#include <cstddef>
#include <cstdint>

#include "tofmat/core/error.hpp"
#include "tofmat/core/npy.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  tofmat::NpyArray a;
  try {
    a = tofmat::parse_npy(data, size);
  } catch (const tofmat::FormatError&) {
    return 0;
  }
  // Accepted: the documented limits must hold and the data must match the shape.
  if (a.shape.empty() || a.shape.size() > tofmat::kNpyMaxDims) __builtin_trap();
  std::size_t n = 1;
  for (std::size_t d : a.shape) n *= d;
  if (n != a.data.size() || n > tofmat::kNpyMaxElements) __builtin_trap();
  return 0;
}
