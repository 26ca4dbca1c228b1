// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The scalar squared-sum kernel of Eq. (12) in integers, its dispatch, and the element-major copy of a table for NEON.
#include "tofmat/core/fixed_distance.hpp"

namespace tofmat {

SquaredSum squared_sum_scalar(const std::int16_t* q, const std::uint8_t* qmask, const std::int16_t* e,
                              const std::uint8_t* emask, std::size_t blocks) {
  SquaredSum out;
  for (std::size_t b = 0; b < blocks; ++b) {
    const unsigned m = emask ? (qmask[b] & emask[b]) : qmask[b];
    if (m == 0) continue;  // nothing valid in both: the common case of a partial query
    for (unsigned j = 0; j < 8; ++j) {
      if (!((m >> j) & 1u)) continue;
      const std::int32_t d = static_cast<std::int32_t>(q[b * 8 + j]) - static_cast<std::int32_t>(e[b * 8 + j]);
      const auto ad = static_cast<std::uint32_t>(d < 0 ? -d : d);
      out.sum += static_cast<std::uint64_t>(ad * ad);  // < 2^32: no wrap in uint32
      ++out.count;
    }
  }
  return out;
}

void squared_sums_scalar(const CompactTable& table, std::size_t block0, std::size_t blocks, const std::int16_t* q,
                         const std::uint8_t* qmask, SquaredSum* acc) {
  for (std::size_t k = 0; k < table.n_candidates(); ++k) {
    const std::uint8_t* em = table.validity(k);
    const SquaredSum s =
        squared_sum_scalar(q, qmask, table.values(k) + block0 * kCompactBlock, em ? em + block0 : nullptr, blocks);
    acc[k].sum += s.sum;
    acc[k].count += s.count;
  }
}

const char* squared_sum_kernel() {
#if defined(__aarch64__)
  return "neon";
#else
  return "scalar";
#endif
}

}  // namespace tofmat

namespace tofmat {

ElementMajorTable::ElementMajorTable(const CompactTable& table)
    : slots((table.n_candidates() + kCompactBlock - 1) / kCompactBlock * kCompactBlock) {
  const std::size_t elements = table.padded_elements(), K = table.n_candidates();
  values.assign(elements * slots, 0);
  gap_row.assign(elements, -1);
  for (std::size_t k = 0; k < K; ++k) {
    if (table.validity(k) != nullptr) gapped.push_back(static_cast<std::uint32_t>(k));
  }
  for (std::size_t e = 0; e < elements; ++e) {
    bool gaps = false;
    for (std::size_t k = 0; k < K; ++k) {
      values[e * slots + k] = table.values(k)[e];
      const std::uint8_t* m = table.validity(k);
      gaps = gaps || (m != nullptr && ((m[e / 8] >> (e % 8)) & 1) == 0);
    }
    if (!gaps) continue;
    gap_row[e] = static_cast<std::int32_t>(gap_lanes.size() / slots);
    for (std::size_t k = 0; k < slots; ++k) {
      const std::uint8_t* m = k < K ? table.validity(k) : nullptr;
      const bool valid = k < K && (m == nullptr || ((m[e / 8] >> (e % 8)) & 1) != 0);
      gap_lanes.push_back(valid ? 0xFFFF : 0);
    }
  }
}

}  // namespace tofmat
