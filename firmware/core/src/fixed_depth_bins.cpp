// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FixedDepthBinAccumulator: the scalar bin-index kernel, the integer sums per bin, and the query of their means.
#include "tofmat/core/fixed_depth_bins.hpp"

#include <cmath>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>

namespace tofmat {

FixedBinning FixedBinning::from(const BinSpec& bins) {
  bins.validate();
  constexpr double kLimitMm = 4194304.0;  // 2^22 mm: start and end in Q8 fit int32
  if (!(std::fabs(bins.start_mm) <= kLimitMm && std::fabs(bins.end_mm()) <= kLimitMm && bins.width_mm >= 1.0 / 64.0)) {
    throw std::invalid_argument("fixed-point bins must lie within +-4194304 mm and be at least 1/64 mm wide");
  }
  FixedBinning b;
  b.start_q8 = static_cast<std::int32_t>(std::llround(bins.start_mm * 256.0));
  b.inv_width = static_cast<std::int32_t>(std::llround(4294967296.0 / (bins.width_mm * 256.0)));
  b.count = bins.count;
  return b;
}

void bin_indices_scalar(const std::int32_t* depth_q8, const std::uint8_t* flags, std::size_t n, const FixedBinning& b,
                        std::int32_t* bin) {
  for (std::size_t i = 0; i < n; ++i) {
    // Offsets in int64: depth - start spans up to 2^32 (both within +-2^31).
    const std::int64_t off = static_cast<std::int64_t>(depth_q8[i]) - b.start_q8;
    const std::int64_t j = off >= 0 ? (off * b.inv_width) >> 32 : -1;
    const bool ok = flags[i] == 0 && depth_q8[i] != kFixedInvalid && j < static_cast<std::int64_t>(b.count);
    bin[i] = ok ? static_cast<std::int32_t>(j) : -1;
  }
}

void bin_indices(FixedKernel kernel, const std::int32_t* depth_q8, const std::uint8_t* flags, std::size_t n,
                 const FixedBinning& b, std::int32_t* bin) {
#if defined(__aarch64__)
  if (kernel == FixedKernel::kBest) return bin_indices_neon(depth_q8, flags, n, b, bin);
#elif defined(__x86_64__)
  if (kernel == FixedKernel::kBest && cpu_has_avx2()) return bin_indices_avx2(depth_q8, flags, n, b, bin);
#endif
  (void)kernel;
  bin_indices_scalar(depth_q8, flags, n, b, bin);
}

FixedDepthBinAccumulator::FixedDepthBinAccumulator(BinSpec bins, std::uint32_t n_rows, std::uint64_t max_count)
    : bins_(bins), fixed_(FixedBinning::from(bins)), n_rows_(n_rows), max_count_(max_count) {
  if (n_rows < 1 || n_rows > 2) throw std::invalid_argument("the decode has two feature rows: n_rows must be 1 or 2");
  if (max_count < 1 || max_count > kMaxCount) throw std::invalid_argument("max_count must be 1..2^32");
  sum_.assign(static_cast<std::size_t>(n_rows_) * bins_.count, 0);
  count_.assign(sum_.size(), 0);
}

std::size_t FixedDepthBinAccumulator::add_frame(const FixedDecodedFrame& f, FixedKernel kernel) {
  const std::size_t n = f.pixels;
  if (f.combined_q8.size() != n || f.flags.size() != n || f.features_q16[0].size() != n ||
      f.features_q16[1].size() != n) {
    throw std::invalid_argument("decoded frame's arrays do not match its pixel count");
  }
  bin_.resize(n);
  bin_indices(kernel, f.combined_q8.data(), f.flags.data(), n, fixed_, bin_.data());
  std::size_t added = 0;
  // The database's two rows, while neither bin is full, without the generic loop (the same sums).
  const bool two = n_rows_ == 2;
  std::int64_t* const sum1 = sum_.data() + bins_.count;
  std::uint64_t* const count1 = count_.data() + bins_.count;
  const std::int32_t* const f0 = f.features_q16[0].data();
  const std::int32_t* const f1 = f.features_q16[1].data();
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t j = bin_[i];
    if (j < 0) continue;
    if (two && count_[static_cast<std::size_t>(j)] < max_count_ && count1[j] < max_count_) {
      sum_[static_cast<std::size_t>(j)] += f0[i];
      ++count_[static_cast<std::size_t>(j)];
      sum1[j] += f1[i];
      ++count1[j];
      ++added;
      continue;
    }
    bool any = false;
    for (std::uint32_t r = 0; r < n_rows_; ++r) {
      const std::size_t k = static_cast<std::size_t>(r) * bins_.count + static_cast<std::size_t>(j);
      if (count_[k] >= max_count_) {
        ++refused_;
        continue;
      }
      sum_[k] += f.features_q16[r][i];
      ++count_[k];
      any = true;
    }
    added += any;
  }
  return added;
}

FixedSurfaceMean surface_mean(const FixedDecodedFrame& f, std::int32_t centre_q8, std::int32_t band_q8) {
  const std::size_t n = f.pixels;
  if (f.combined_q8.size() != n || f.flags.size() != n || f.features_q16[0].size() != n ||
      f.features_q16[1].size() != n) {
    throw std::invalid_argument("decoded frame's arrays do not match its pixel count");
  }
  if (band_q8 < 0) throw std::invalid_argument("the surface's band must not be negative");
  FixedSurfaceMean s;
  const std::int64_t lo = static_cast<std::int64_t>(centre_q8) - band_q8;
  const std::int64_t hi = static_cast<std::int64_t>(centre_q8) + band_q8;
  const auto counts = [&](std::size_t i) {
    const std::int32_t z = f.combined_q8[i];
    return f.flags[i] == 0 && z != kFixedInvalid && z >= lo && z <= hi;
  };
  const std::int32_t* const z = f.combined_q8.data();
  const std::uint8_t* const flags = f.flags.data();
  const std::int32_t* const f0 = f.features_q16[0].data();
  const std::int32_t* const f1 = f.features_q16[1].data();
  // The reference features: the counted pixel nearest the centre's depth (the
  // first of the nearest). The profiles' centre is the region's median, a
  // valid pixel's depth: the first pixel at it is that one, found without
  // measuring every gap (blocks of 16 tested branch-free, then the block).
  std::size_t ref = n;
  if (centre_q8 != kFixedInvalid) {
    constexpr std::size_t kBlock = 16;
    std::size_t i = 0;
    for (; i + kBlock <= n && ref == n; i += kBlock) {
      unsigned hit = 0;
      for (std::size_t j = i; j < i + kBlock; ++j) hit |= static_cast<unsigned>((flags[j] == 0) & (z[j] == centre_q8));
      if (hit == 0) continue;
      for (std::size_t j = i; j < i + kBlock; ++j) {
        if (flags[j] == 0 && z[j] == centre_q8) {
          ref = j;
          break;
        }
      }
    }
    for (; i < n && ref == n; ++i)
      if (flags[i] == 0 && z[i] == centre_q8) ref = i;
  }
  if (ref == n) {
    std::int64_t nearest = std::numeric_limits<std::int64_t>::max();
    for (std::size_t i = 0; i < n; ++i) {
      const std::int64_t gap = std::llabs(static_cast<std::int64_t>(z[i]) - centre_q8);
      if (counts(i) && gap < nearest) {
        nearest = gap;
        ref = i;
      }
    }
  }
  if (ref == n) return s;
  constexpr std::int64_t kSameWrapQ16 = static_cast<std::int64_t>(kSurfaceSameWrapMm) * 65536;
  const std::int64_t r0 = f0[ref], r1 = f1[ref];
  // (branch-free: the compiler keeps it in vector lanes)
  std::int64_t depth_sum = 0;  // |depth| < 2^31 each, at most 2^32 pixels: below 2^63
  std::int64_t sum0 = 0, sum1 = 0;
  std::uint64_t pixels = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::int64_t zi = z[i], d0 = f0[i] - r0, d1 = f1[i] - r1;
    const bool in = (flags[i] == 0) & (zi != kFixedInvalid) & (zi >= lo) & (zi <= hi) & (d0 >= -kSameWrapQ16) &
                    (d0 <= kSameWrapQ16) & (d1 >= -kSameWrapQ16) & (d1 <= kSameWrapQ16);
    const std::int64_t keep = -static_cast<std::int64_t>(in);  // all ones or zero
    depth_sum += zi & keep;
    sum0 += f0[i] & keep;
    sum1 += f1[i] & keep;
    pixels += static_cast<std::uint64_t>(in);
  }
  s.sum_q16[0] = sum0;
  s.sum_q16[1] = sum1;
  s.pixels = pixels;
  // Floor division (the mean lies between the pixels' depths: it fits int32).
  const auto count = static_cast<std::int64_t>(s.pixels);
  std::int64_t q = depth_sum / count;
  if (depth_sum % count != 0 && depth_sum < 0) --q;
  s.depth_q8 = static_cast<std::int32_t>(q);
  return s;
}

std::size_t FixedDepthBinAccumulator::add_surface(const FixedSurfaceMean& s) {
  if (s.pixels == 0 || s.depth_q8 == kFixedInvalid) return 0;
  const std::uint8_t valid = 0;
  std::int32_t j = -1;
  bin_indices_scalar(&s.depth_q8, &valid, 1, fixed_, &j);
  if (j < 0) return 0;
  for (std::uint32_t r = 0; r < n_rows_; ++r) {
    if (count_[static_cast<std::size_t>(r) * bins_.count + static_cast<std::size_t>(j)] + s.pixels > max_count_) {
      refused_ += s.pixels;
      return 0;
    }
  }
  for (std::uint32_t r = 0; r < n_rows_; ++r) {
    const std::size_t k = static_cast<std::size_t>(r) * bins_.count + static_cast<std::size_t>(j);
    sum_[k] += s.sum_q16[r];
    count_[k] += s.pixels;
  }
  return static_cast<std::size_t>(s.pixels);
}

std::vector<float> FixedDepthBinAccumulator::query(std::uint64_t min_count) const {
  std::vector<float> out(sum_.size(), std::numeric_limits<float>::quiet_NaN());
  const std::uint64_t need = min_count < 1 ? 1 : min_count;
  for (std::size_t k = 0; k < sum_.size(); ++k) {
    if (count_[k] >= need) {
      out[k] = static_cast<float>(static_cast<double>(sum_[k]) / 65536.0 / static_cast<double>(count_[k]));
    }
  }
  return out;
}

std::uint64_t FixedDepthBinAccumulator::count(std::uint32_t row, std::uint32_t bin) const {
  if (row >= n_rows_ || bin >= bins_.count) throw std::out_of_range("row or bin outside the accumulator");
  return count_[static_cast<std::size_t>(row) * bins_.count + bin];
}

std::uint32_t FixedDepthBinAccumulator::bins_covered(std::uint64_t min_count) const {
  std::uint32_t n = 0;
  for (std::uint32_t j = 0; j < bins_.count; ++j) {
    bool any = false;
    for (std::uint32_t r = 0; r < n_rows_; ++r)
      any = any || count_[static_cast<std::size_t>(r) * bins_.count + j] >= std::max<std::uint64_t>(1, min_count);
    n += any;
  }
  return n;
}

void FixedDepthBinAccumulator::reset() {
  std::fill(sum_.begin(), sum_.end(), 0);
  std::fill(count_.begin(), count_.end(), 0);
  refused_ = 0;
}

}  // namespace tofmat
