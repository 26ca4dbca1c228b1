// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Eq. (12) in fixed point: the query quantised to the table's step, the
// table held as a CompactTable, squared differences summed in integers by the
// build's kernel (NEON on aarch64: over an element-major copy of the table,
// ElementMajorTable), candidates ranked by exact comparison of
// the rationals sum / count. Same contract as FloatClassifier (errors, ties to
// the lower table index, candidates without a common element left out); the
// ordering is that of the float path on the quantised values (docs/numerics.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "tofmat/core/classifier.hpp"
#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/fixed_distance.hpp"
#include "tofmat/core/fixed_kernel.hpp"

namespace tofmat {

class FixedClassifier {
 public:
  // candidates: indices into the table (empty: all); only these are held.
  // kernel: the build's best squared-sum kernel, or the scalar one (tests, benchmarks).
  explicit FixedClassifier(std::shared_ptr<const ExemplarTable> table, std::vector<std::uint32_t> candidates = {},
                           FixedKernel kernel = FixedKernel::kBest);

  // A query in the table's units: int16 steps and validity in the padded
  // layout, and per row the blocks holding valid elements.
  struct Prepared {
    std::vector<std::int16_t> q;
    std::vector<std::uint8_t> mask;
    std::vector<std::size_t> first, last;  // per row: blocks [first, last)
  };
  // Validates and quantises (the errors of classify()).
  Prepared prepare(const float* query, std::size_t n) const;
  // Squared sums of every candidate (in candidates() order) for a prepared query.
  std::vector<SquaredSum> squared_sums(const Prepared& p) const;
  // The same into out[0 .. n_candidates) (zeroed first): no allocation.
  void squared_sums(const Prepared& p, SquaredSum* out) const;

  // query: n_rows x n_bins, C order, NaN = missing. Throws
  // std::invalid_argument as FloatClassifier does. A value beyond +-32767
  // steps (+-256 mm for the real database's 2^-7 mm) saturates there, and the
  // ranking is that of the saturated query (docs/numerics.md: the headroom).
  Classification classify(const float* query, std::size_t n) const;

  const ExemplarTable& table() const { return *table_; }
  const CompactTable& compact() const { return compact_; }
  const std::vector<std::uint32_t>& candidates() const { return compact_.candidates(); }

 private:
  std::shared_ptr<const ExemplarTable> table_;
  CompactTable compact_;
  FixedKernel kernel_;
#if defined(__aarch64__)
  std::unique_ptr<const ElementMajorTable> elements_;  // the NEON kernel's layout (kBest only)
#endif
};

}  // namespace tofmat
