// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Builds the CompactTable: the candidates' exemplars quantised to int16 table steps, padded rows and validity bitsets.
#include "tofmat/core/compact_table.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "tofmat/core/table_file.hpp"

namespace tofmat {

std::int16_t quantise_to_step(float value_mm, double inv_step) {
  const double q = std::round(static_cast<double>(value_mm) * inv_step);
  return static_cast<std::int16_t>(std::clamp(q, -32767.0, 32767.0));
}

double compact_step_mm(const ExemplarTable& table) {
  // A table read from a .tmx file keeps the file's step (the same int16 values
  // bit for bit). One built from floats gets four times the step that would
  // just fit its largest value: queries share the int16 range, and a query
  // element beyond it saturates, which can reorder candidates; 2 bits of
  // headroom keep real queries (noise, outliers of a few times the table's
  // range) inside it.
  return table.quant_step_mm() > 0.0 ? table.quant_step_mm() : 4.0 * choose_quant_step_mm(table);
}

double fixed_query_limit_mm(const ExemplarTable& table) { return 32767.0 * compact_step_mm(table); }

CompactTable::CompactTable(const ExemplarTable& table, std::vector<std::uint32_t> candidates)
    : n_rows_(table.n_rows()),
      n_bins_(table.n_bins()),
      candidates_(candidate_indices(table.n_materials(), std::move(candidates))) {
  step_mm_ = compact_step_mm(table);
  const double inv = 1.0 / step_mm_;
  padded_bins_ = (n_bins_ + kCompactBlock - 1) / kCompactBlock * kCompactBlock;
  const std::size_t len = padded_elements();
  values_.assign(candidates_.size() * len, 0);
  mask_offset_.assign(candidates_.size(), -1);
  std::vector<std::uint8_t> bits(len / kCompactBlock);
  for (std::size_t k = 0; k < candidates_.size(); ++k) {
    const float* src = table.material_values(candidates_[k]);
    std::fill(bits.begin(), bits.end(), 0);
    bool all_valid = true;
    for (std::uint32_t r = 0; r < n_rows_; ++r) {
      for (std::uint32_t b = 0; b < n_bins_; ++b) {
        const float v = src[static_cast<std::size_t>(r) * n_bins_ + b];
        const std::size_t i = static_cast<std::size_t>(r) * padded_bins_ + b;
        if (std::isnan(v)) {
          all_valid = false;
          continue;
        }
        values_[k * len + i] = quantise_to_step(v, inv);
        bits[i / kCompactBlock] = static_cast<std::uint8_t>(bits[i / kCompactBlock] | (1u << (i % kCompactBlock)));
      }
    }
    // (Padding needs no bit: a query's bitset never marks padding valid.)
    if (all_valid) continue;
    mask_offset_[k] = static_cast<std::int32_t>(masks_.size());
    masks_.insert(masks_.end(), bits.begin(), bits.end());
  }
}

std::size_t CompactTable::memory_bytes() const {
  return values_.size() * sizeof(std::int16_t) + masks_.size() + mask_offset_.size() * sizeof(std::int32_t) +
         candidates_.size() * sizeof(std::uint32_t) + sizeof(*this);
}

}  // namespace tofmat
