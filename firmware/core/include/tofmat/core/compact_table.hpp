// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The exemplar table as the fixed-point classifier holds it in memory
// (docs/numerics.md): int16 multiples of the table's power-of-two step, each
// row padded to a multiple of kCompactBlock elements for SIMD, a validity
// bitset only for the materials that miss elements, and only the candidate
// materials asked for (the subset is applied when the table is built, so a
// profile that needs three materials holds three).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "tofmat/core/exemplar_table.hpp"

namespace tofmat {

// Elements per SIMD block (one NEON int16x8 register) and per validity byte.
inline constexpr std::size_t kCompactBlock = 8;

// The step a CompactTable of `table` quantises with (see its constructor).
double compact_step_mm(const ExemplarTable& table);
// The largest query value, in mm, the fixed-point path holds for `table`
// without saturating: 32767 steps. Beyond it the fixed path ranks the
// saturated value and the float path the value itself, so the two may
// answer differently (docs/numerics.md: the headroom).
double fixed_query_limit_mm(const ExemplarTable& table);

class CompactTable {
 public:
  // candidates: indices into `table` (empty: all), kept in increasing order
  // without duplicates. Values are quantised with the table's own step if it
  // came from a .tmx file (exactly what the file holds), else with four times
  // the smallest power-of-two step that fits the largest value in int16
  // (choose_quant_step_mm): headroom for queries beyond the table's values.
  // Throws std::invalid_argument on an index out of range.
  explicit CompactTable(const ExemplarTable& table, std::vector<std::uint32_t> candidates = {});

  double step_mm() const { return step_mm_; }
  std::uint32_t n_rows() const { return n_rows_; }
  std::uint32_t n_bins() const { return n_bins_; }
  std::size_t padded_bins() const { return padded_bins_; }  // a multiple of kCompactBlock
  std::size_t padded_elements() const { return static_cast<std::size_t>(n_rows_) * padded_bins_; }
  std::size_t n_candidates() const { return candidates_.size(); }
  // Candidate k's index in the source table.
  const std::vector<std::uint32_t>& candidates() const { return candidates_; }

  // Candidate k's values: n_rows x padded_bins, 0 where missing or padding.
  const std::int16_t* values(std::size_t k) const { return values_.data() + k * padded_elements(); }
  // Candidate k's validity (bit i % 8 of byte i / 8 for element i of the
  // padded layout), or nullptr when every element of the candidate is valid
  // (padding included: the query's bitset never marks padding valid).
  const std::uint8_t* validity(std::size_t k) const {
    return mask_offset_[k] < 0 ? nullptr : masks_.data() + mask_offset_[k];
  }
  // What the table occupies: values, bitsets, their offsets and the candidate indices.
  std::size_t memory_bytes() const;

 private:
  double step_mm_ = 0.0;
  std::uint32_t n_rows_ = 0, n_bins_ = 0;
  std::size_t padded_bins_ = 0;
  std::vector<std::uint32_t> candidates_;
  std::vector<std::int16_t> values_;
  std::vector<std::uint8_t> masks_;
  std::vector<std::int32_t> mask_offset_;  // into masks_, -1: all valid
};

// A float value in table steps: round to nearest (ties away from zero),
// saturated to [-32767, 32767]. The query side of the fixed-point path.
std::int16_t quantise_to_step(float value_mm, double inv_step);

}  // namespace tofmat
