// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: decode_table on arbitrary bytes. Only tofmat::FormatError
// is an acceptable refusal; any other exception, crash or sanitizer report is
// a finding.
//
// A random mutation almost never carries a valid CRC-32, which would stop the
// fuzzer at the checksum; so each input is also decoded with its last four
// bytes replaced by the correct CRC, reaching the content checks behind it.
#include <zlib.h>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "tofmat/core/error.hpp"
#include "tofmat/core/table_file.hpp"

namespace {

void check(const std::uint8_t* data, std::size_t size) {
  std::optional<tofmat::ExemplarTable> t;
  try {
    t.emplace(tofmat::decode_table(data, size));
  } catch (const tofmat::FormatError&) {
    return;  // refused: fine
  }
  // Whatever decodes is a valid table: its own encoding must decode again, to
  // the same names, rows and bins (values may be requantised to another step).
  const auto again = tofmat::encode_table(*t);
  const tofmat::ExemplarTable u = tofmat::decode_table(again.data(), again.size());
  if (u.materials() != t->materials() || !(u.rows() == t->rows()) || !(u.bins() == t->bins())) __builtin_trap();
  if (u.distortion().has_value() != t->distortion().has_value()) __builtin_trap();
  if (t->distortion() && !(u.distortion()->grid == t->distortion()->grid)) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  check(data, size);
  if (size >= 4 && size <= tofmat::kTableMaxFileBytes) {
    std::vector<std::uint8_t> fixed(data, data + size);
    const uLong crc = crc32(crc32(0L, Z_NULL, 0), fixed.data(), static_cast<uInt>(size - 4));
    for (int i = 0; i < 4; ++i)
      fixed[size - 4 + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(crc >> (8 * i));
    check(fixed.data(), fixed.size());
  }
  return 0;
}
