// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// What a learned classifier's ONNX model must say about itself before tofmat
// runs it (docs/learned-models.md): the contract version, and the table it
// was trained for (materials in order, rows, depth bins), held in the model's
// metadata properties. Its input "query" is a batch of queries as the
// depth-bin accumulators give them (n_rows x n_bins floats, C order, NaN =
// missing); its output "probabilities" one probability per material.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tofmat/core/bin_spec.hpp"
#include "tofmat/core/exemplar_table.hpp"

namespace tofmat::learn {

// The contract version this build understands: a model of the same major
// version runs (a newer minor adds only what older readers may ignore).
inline constexpr int kContractMajor = 1;
inline constexpr int kContractMinor = 0;
inline constexpr const char* kInputName = "query";
inline constexpr const char* kOutputName = "probabilities";
// Metadata keys.
inline constexpr const char* kKeyContract = "tofmat.contract";    // "1.0"
inline constexpr const char* kKeyMaterials = "tofmat.materials";  // names, one per line
inline constexpr const char* kKeyRows = "tofmat.rows";            // "2"
inline constexpr const char* kKeyBins = "tofmat.bins";            // "start_mm width_mm count"
// Optional: the confidence's temperature by sweep length, fitted by tofmat
// train on tuning-side sessions: "bins:T bins:T ..." (confidence.hpp).
inline constexpr const char* kKeyTemperatures = "tofmat.temperatures";
// Optional: the CRC-32 of the curves the model was trained on (curves_crc32()),
// 8 hex digits: a table with the same materials and bins but other curves (a
// simulated table, a material re-captured) is refused.
inline constexpr const char* kKeyCurves = "tofmat.curves_crc32";
inline constexpr std::size_t kMaxTemperatureKnots = 64;
// Bounds on what the metadata may hold (checked before anything is parsed).
inline constexpr std::size_t kMaxMetadataValue = 64 * 1024;
inline constexpr std::size_t kMaxMaterials = 4096;

struct ModelContract {
  int major = 0;
  int minor = 0;
  std::vector<std::string> materials;
  std::uint32_t rows = 0;
  BinSpec bins;
  // (sweep length in bins, temperature) knots; empty: temperature 1 (the
  // model's own probabilities).
  std::vector<std::pair<double, double>> temperatures;
  std::optional<std::uint32_t> curves_crc32;
};

// zlib's CRC-32 of the table's values as little-endian float32, NaN as
// 0x7fc00000 (what tofmat.learn.ModelContract.of_table computes too).
std::uint32_t curves_crc32(const ExemplarTable& table);

// Parses the contract from the model's metadata. Throws std::invalid_argument
// naming the key that is missing, too long or malformed, or a major version
// this build does not run.
ModelContract parse_contract(const std::map<std::string, std::string>& metadata);

// Throws std::invalid_argument saying how the model and the table differ
// (materials, their order, rows or bins): a model runs only on the table it
// was trained for.
void check_table(const ModelContract& contract, const ExemplarTable& table);

}  // namespace tofmat::learn
