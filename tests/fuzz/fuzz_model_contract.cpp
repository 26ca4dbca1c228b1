// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: a learned model's metadata (firmware/learn/model_contract.hpp),
// what tofmat reads from a model file itself before onnxruntime runs it. The
// input is split at NUL bytes into the values of tofmat.contract,
// tofmat.materials, tofmat.rows, tofmat.bins, tofmat.temperatures and
// tofmat.curves_crc32 (a missing part is a missing key); any input ends in a
// contract or std::invalid_argument, and a contract is checked against a
// small table the same way.
#include <cstdint>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>

#include "tofmat/learn/model_contract.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const auto table = std::make_shared<const tofmat::ExemplarTable>(
      std::vector<std::string>{"cork", "wood"}, std::vector<tofmat::RowSpec>{{80, 120}, {16, 120}},
      tofmat::BinSpec{600.0, 3.0, 4}, std::vector<float>(2 * 2 * 4, 1.0F));
  static const char* const keys[] = {tofmat::learn::kKeyContract,     tofmat::learn::kKeyMaterials,
                                     tofmat::learn::kKeyRows,         tofmat::learn::kKeyBins,
                                     tofmat::learn::kKeyTemperatures, tofmat::learn::kKeyCurves};
  std::map<std::string, std::string> metadata;
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::size_t start = 0;
  for (const char* key : keys) {
    if (start > text.size()) break;
    const auto end = text.find('\0', start);
    metadata[key] = text.substr(start, end == std::string::npos ? std::string::npos : end - start);
    if (end == std::string::npos) break;
    start = end + 1;
  }
  try {
    const auto contract = tofmat::learn::parse_contract(metadata);
    if (contract.materials.empty() || contract.rows == 0) __builtin_trap();  // refused, never accepted
    tofmat::learn::check_table(contract, *table);
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
