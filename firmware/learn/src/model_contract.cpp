// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
#include "tofmat/learn/model_contract.hpp"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include <zlib.h>

#include "tofmat/core/confidence.hpp"

namespace tofmat::learn {
namespace {

const std::string& value_of(const std::map<std::string, std::string>& metadata, const char* key) {
  const auto it = metadata.find(key);
  if (it == metadata.end())
    throw std::invalid_argument(std::string("model metadata: no \"") + key +
                                "\" (not a tofmat model: docs/learned-models.md)");
  if (it->second.size() > kMaxMetadataValue)
    throw std::invalid_argument(std::string("model metadata: \"") + key + "\" is longer than " +
                                std::to_string(kMaxMetadataValue) + " bytes");
  return it->second;
}

// A whole non-negative decimal integer, at most `max`.
long parse_count(const std::string& text, const char* key, long max) {
  if (text.empty() || text.size() > 9 || text.find_first_not_of("0123456789") != std::string::npos)
    throw std::invalid_argument(std::string("model metadata: \"") + key + "\" is not a count: \"" + text + "\"");
  const long v = std::strtol(text.c_str(), nullptr, 10);
  if (v > max)
    throw std::invalid_argument(std::string("model metadata: \"") + key + "\" is over " + std::to_string(max));
  return v;
}

}  // namespace

ModelContract parse_contract(const std::map<std::string, std::string>& metadata) {
  ModelContract c;
  const std::string& version = value_of(metadata, kKeyContract);
  const auto dot = version.find('.');
  if (dot == std::string::npos)
    throw std::invalid_argument("model metadata: \"tofmat.contract\" is not major.minor: \"" + version + "\"");
  c.major = static_cast<int>(parse_count(version.substr(0, dot), kKeyContract, 1000));
  c.minor = static_cast<int>(parse_count(version.substr(dot + 1), kKeyContract, 1000));
  if (c.major != kContractMajor)
    throw std::invalid_argument("model contract " + version + ": this build runs " + std::to_string(kContractMajor) +
                                ".x models");

  std::istringstream names(value_of(metadata, kKeyMaterials));
  for (std::string line; std::getline(names, line);) {
    if (line.empty()) throw std::invalid_argument("model metadata: an empty material name in \"tofmat.materials\"");
    if (c.materials.size() == kMaxMaterials)
      throw std::invalid_argument("model metadata: more than " + std::to_string(kMaxMaterials) + " materials");
    c.materials.push_back(line);
  }
  if (c.materials.empty()) throw std::invalid_argument("model metadata: \"tofmat.materials\" names no material");

  c.rows = static_cast<std::uint32_t>(parse_count(value_of(metadata, kKeyRows), kKeyRows, 64));
  if (c.rows == 0) throw std::invalid_argument("model metadata: \"tofmat.rows\" is 0");

  std::istringstream bins(value_of(metadata, kKeyBins));
  double start = NAN, width = NAN;
  std::string count, rest;
  if (!(bins >> start >> width >> count) || (bins >> rest))
    throw std::invalid_argument("model metadata: \"tofmat.bins\" is not \"start_mm width_mm count\"");
  c.bins.start_mm = start;
  c.bins.width_mm = width;
  c.bins.count = static_cast<std::uint32_t>(parse_count(count, kKeyBins, 1000000));
  try {
    c.bins.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("model metadata: \"tofmat.bins\": ") + e.what());
  }

  if (metadata.count(kKeyCurves)) {
    const std::string& hex = value_of(metadata, kKeyCurves);
    if (hex.size() != 8 || hex.find_first_not_of("0123456789abcdef") != std::string::npos)
      throw std::invalid_argument("model metadata: \"tofmat.curves_crc32\" is not 8 lowercase hex digits");
    c.curves_crc32 = static_cast<std::uint32_t>(std::stoul(hex, nullptr, 16));
  }

  if (metadata.count(kKeyTemperatures)) {
    std::istringstream knots(value_of(metadata, kKeyTemperatures));
    for (std::string knot; knots >> knot;) {
      if (c.temperatures.size() == kMaxTemperatureKnots)
        throw std::invalid_argument("model metadata: more than " + std::to_string(kMaxTemperatureKnots) +
                                    " temperature knots");
      const auto colon = knot.find(':');
      std::size_t used_bins = 0, used_t = 0;
      double bins_v = NAN, t = NAN;
      try {
        if (colon == std::string::npos) throw std::invalid_argument("no colon");
        bins_v = std::stod(knot.substr(0, colon), &used_bins);
        t = std::stod(knot.substr(colon + 1), &used_t);
      } catch (const std::exception&) {  // invalid_argument or out_of_range
        used_bins = 0;
      }
      if (used_bins == 0 || used_bins != colon || used_t != knot.size() - colon - 1)
        throw std::invalid_argument("model metadata: \"tofmat.temperatures\" is not \"bins:T ...\": \"" + knot + "\"");
      c.temperatures.emplace_back(bins_v, t);
    }
    try {
      Calibration{c.temperatures, {}}.validate();
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(std::string("model metadata: \"tofmat.temperatures\": ") + e.what());
    }
  }
  return c;
}

void check_table(const ModelContract& contract, const ExemplarTable& table) {
  if (contract.rows != table.n_rows() || contract.bins.count != table.bins().count)
    throw std::invalid_argument("the model takes " + std::to_string(contract.rows) + " x " +
                                std::to_string(contract.bins.count) + " queries, the table's are " +
                                std::to_string(table.n_rows()) + " x " + std::to_string(table.bins().count));
  // The table file stores the bins in float32 on some paths: compare to 1e-6.
  const auto close = [](double a, double b) { return std::fabs(a - b) <= 1e-6 * std::max(1.0, std::fabs(b)); };
  if (!close(contract.bins.start_mm, table.bins().start_mm) || !close(contract.bins.width_mm, table.bins().width_mm))
    throw std::invalid_argument("the model's depth bins are not the table's");
  const auto& names = table.materials();
  if (contract.materials.size() != names.size())
    throw std::invalid_argument("the model knows " + std::to_string(contract.materials.size()) +
                                " materials, the table " + std::to_string(names.size()));
  for (std::size_t i = 0; i < names.size(); ++i)
    if (contract.materials[i] != names[i])
      throw std::invalid_argument("the model's material " + std::to_string(i) + " is \"" + contract.materials[i] +
                                  "\", the table's \"" + names[i] + "\" (train the model on this table)");
  if (contract.curves_crc32 && *contract.curves_crc32 != curves_crc32(table))
    throw std::invalid_argument(
        "the table's curves are not the ones the model was trained on (same materials and bins, other values: "
        "train the model on this table)");
}

std::uint32_t curves_crc32(const ExemplarTable& table) {
  uLong crc = crc32(0L, Z_NULL, 0);
  std::uint8_t bytes[4];
  for (const float v : table.values()) {
    std::uint32_t bits = 0x7fc00000U;
    if (!std::isnan(v)) std::memcpy(&bits, &v, sizeof bits);
    for (int i = 0; i < 4; ++i) bytes[i] = static_cast<std::uint8_t>(bits >> (8 * i));
    crc = crc32(crc, bytes, 4);
  }
  return static_cast<std::uint32_t>(crc);
}

}  // namespace tofmat::learn
