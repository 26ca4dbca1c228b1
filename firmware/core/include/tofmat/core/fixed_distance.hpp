// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Eq. (12) in integers: the kernel that sums squared differences between a
// query and an exemplar over the elements valid in both, in table steps
// (docs/numerics.md). Scalar C++ everywhere; NEON on aarch64, selected at
// compile time. Both give the same integers bit for bit (tests/cpp/
// test_fixed_classifier.cpp runs them side by side under qemu-aarch64).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/fixed_kernel.hpp"

namespace tofmat {

// Sum of (q - e)^2 and the count of elements valid in both.
//   q, e: int16 in [-32767, 32767] (a difference fits 17 bits, its square
//         uint32: 65534^2 < 2^32); the sum is uint64 (2^32 per element, so
//         2^32 elements before it could wrap: a table has at most 2^20).
//   qmask: the query's validity, bit i % 8 of byte i / 8; emask the
//          exemplar's, or nullptr when all its elements are valid.
//   blocks: elements / 8 (whole blocks of kCompactBlock).
struct SquaredSum {
  std::uint64_t sum = 0;
  std::uint32_t count = 0;
  bool operator==(const SquaredSum& o) const { return sum == o.sum && count == o.count; }
};

SquaredSum squared_sum_scalar(const std::int16_t* q, const std::uint8_t* qmask, const std::int16_t* e,
                              const std::uint8_t* emask, std::size_t blocks);
#if defined(__aarch64__)
SquaredSum squared_sum_neon(const std::int16_t* q, const std::uint8_t* qmask, const std::int16_t* e,
                            const std::uint8_t* emask, std::size_t blocks);
#endif

// The build's kernel: NEON on aarch64, scalar elsewhere.
inline SquaredSum squared_sum(const std::int16_t* q, const std::uint8_t* qmask, const std::int16_t* e,
                              const std::uint8_t* emask, std::size_t blocks) {
#if defined(__aarch64__)
  return squared_sum_neon(q, qmask, e, emask, blocks);
#else
  return squared_sum_scalar(q, qmask, e, emask, blocks);
#endif
}

// The same for every candidate of a table at once, over the blocks
// [block0, block0 + blocks) of its padded layout (one row's range of a
// query): q and qmask point at the query's block0; adds into acc[k] for
// candidate k. One call per query row instead of one per candidate and row:
// a short query (a few bins) costs little more than its arithmetic.
void squared_sums_scalar(const CompactTable& table, std::size_t block0, std::size_t blocks, const std::int16_t* q,
                         const std::uint8_t* qmask, SquaredSum* acc);
#if defined(__aarch64__)
void squared_sums_neon(const CompactTable& table, std::size_t block0, std::size_t blocks, const std::int16_t* q,
                       const std::uint8_t* qmask, SquaredSum* acc);
#endif
inline void squared_sums(FixedKernel kernel, const CompactTable& table, std::size_t block0, std::size_t blocks,
                         const std::int16_t* q, const std::uint8_t* qmask, SquaredSum* acc) {
#if defined(__aarch64__)
  if (kernel == FixedKernel::kBest) return squared_sums_neon(table, block0, blocks, q, qmask, acc);
#endif
  (void)kernel;
  squared_sums_scalar(table, block0, blocks, q, qmask, acc);
}

// The compact table rearranged element-major (each element's candidates side
// by side, padded to a multiple of 8; validity lanes only for the elements
// where some candidate is missing), for the NEON kernel that goes over a
// query's valid elements once and keeps every candidate's sum in vector lanes:
// a short query then costs its elements, not its candidates times its blocks.
// A copy of the values (the real database: 25.6 KB beside the 23.7 KB table);
// FixedClassifier builds it on aarch64 only.
struct ElementMajorTable {
  std::size_t slots = 0;                 // candidates rounded up to 8
  std::vector<std::int16_t> values;      // element * slots + k (0 for padding)
  std::vector<std::int32_t> gap_row;     // per element: its row of gap_lanes, or -1 (every candidate valid)
  std::vector<std::uint16_t> gap_lanes;  // 0xFFFF where candidate k is valid at the element, else 0
  std::vector<std::uint32_t> gapped;     // the candidates with a validity bitset
  explicit ElementMajorTable(const CompactTable& table);
};
struct BlockRange {
  std::size_t block0 = 0, blocks = 0;  // blocks [block0, block0 + blocks) of the padded layout
};
#if defined(__aarch64__)
// The same sums as squared_sums_scalar over every range at once (q and qmask
// are the whole query's, in the padded layout; a query's rows in one call).
void squared_sums_elements_neon(const ElementMajorTable& em, const CompactTable& table, const BlockRange* ranges,
                                std::size_t n_ranges, const std::int16_t* q, const std::uint8_t* qmask,
                                SquaredSum* acc);
#endif

// The name of the build's kernel ("neon" or "scalar"), for benchmarks and logs.
const char* squared_sum_kernel();

}  // namespace tofmat
