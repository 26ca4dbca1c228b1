// Eq. (12) in fixed point: the query quantised to the table's step, the
// table held as a CompactTable, squared differences summed in integers by the
// build's kernel (NEON on aarch64), candidates ranked by exact comparison of
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

namespace tofmat {

class FixedClassifier {
 public:
  // candidates: indices into the table (empty: all); only these are held.
  explicit FixedClassifier(std::shared_ptr<const ExemplarTable> table, std::vector<std::uint32_t> candidates = {});

  // query: n_rows x n_bins, C order, NaN = missing. Throws
  // std::invalid_argument as FloatClassifier does. A value beyond +-32767
  // steps (+-256 mm for the real database's 2^-7 mm) saturates there: far
  // outside every exemplar, it still ranks last-but-equal (docs/numerics.md).
  Classification classify(const float* query, std::size_t n) const;

  const ExemplarTable& table() const { return *table_; }
  const CompactTable& compact() const { return compact_; }
  const std::vector<std::uint32_t>& candidates() const { return compact_.candidates(); }

 private:
  std::shared_ptr<const ExemplarTable> table_;
  CompactTable compact_;
};

}  // namespace tofmat
