// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The NEON kernel of squared_sum (aarch64 only; see fixed_distance.hpp).
// Per block of 8: absolute differences widen to uint32 (vabdl), square in
// uint32 (no wrap: < 2^32) and pairwise-add into uint64 lanes; a partly valid
// block's validity byte becomes a lane mask (vtst against each lane's bit).
// Two blocks a step, and wholly valid pairs skip the masks.
#include "tofmat/core/fixed_distance.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>

namespace tofmat {

namespace {

// The squares of one block's absolute differences, in two uint32x4 halves.
inline void block_squares(const std::int16_t* q, const std::int16_t* e, uint32x4_t& lo, uint32x4_t& hi) {
  const int16x8_t qv = vld1q_s16(q), ev = vld1q_s16(e);
  lo = vreinterpretq_u32_s32(vabdl_s16(vget_low_s16(qv), vget_low_s16(ev)));
  hi = vreinterpretq_u32_s32(vabdl_high_s16(qv, ev));
  lo = vmulq_u32(lo, lo);
  hi = vmulq_u32(hi, hi);
}

// A partly valid block: squares masked by the validity byte m.
inline void masked_block(const std::int16_t* q, const std::int16_t* e, unsigned m, uint16x8_t lane_bits,
                         uint64x2_t& acc, std::uint32_t& count) {
  uint32x4_t lo, hi;
  block_squares(q, e, lo, hi);
  count += static_cast<std::uint32_t>(__builtin_popcount(m));
  const uint16x8_t lanes = vtstq_u16(vdupq_n_u16(static_cast<std::uint16_t>(m)), lane_bits);
  // 0xFFFF lanes widen (as signed) to 0xFFFFFFFF.
  lo = vandq_u32(lo, vreinterpretq_u32_s32(vmovl_s16(vreinterpret_s16_u16(vget_low_u16(lanes)))));
  hi = vandq_u32(hi, vreinterpretq_u32_s32(vmovl_high_s16(vreinterpretq_s16_u16(lanes))));
  acc = vpadalq_u32(acc, lo);
  acc = vpadalq_u32(acc, hi);
}

const std::uint16_t kLaneBits[8] = {1, 2, 4, 8, 16, 32, 64, 128};

inline SquaredSum squared_sum_body(const std::int16_t* q, const std::uint8_t* qmask, const std::int16_t* e,
                                   const std::uint8_t* emask, std::size_t blocks, uint16x8_t lane_bits) {
  uint64x2_t acc = vdupq_n_u64(0);
  std::uint32_t count = 0;
  const auto valid = [&](std::size_t b) -> unsigned { return emask ? (qmask[b] & emask[b]) : qmask[b]; };
  std::size_t b = 0;
  // Two blocks a step; both wholly valid (the inside of a sweep) needs no lane masks.
  for (; b + 2 <= blocks; b += 2) {
    const unsigned m0 = valid(b), m1 = valid(b + 1);
    if ((m0 & m1) == 0xFFu) {
      uint32x4_t lo0, hi0, lo1, hi1;
      block_squares(q + b * 8, e + b * 8, lo0, hi0);
      block_squares(q + b * 8 + 8, e + b * 8 + 8, lo1, hi1);
      acc = vpadalq_u32(acc, lo0);  // (squares < 2^32 each, but not their sums: widen each)
      acc = vpadalq_u32(acc, hi0);
      acc = vpadalq_u32(acc, lo1);
      acc = vpadalq_u32(acc, hi1);
      count += 16;
      continue;
    }
    if (m0) masked_block(q + b * 8, e + b * 8, m0, lane_bits, acc, count);
    if (m1) masked_block(q + b * 8 + 8, e + b * 8 + 8, m1, lane_bits, acc, count);
  }
  if (b < blocks) {
    const unsigned m = valid(b);
    if (m) masked_block(q + b * 8, e + b * 8, m, lane_bits, acc, count);
  }
  SquaredSum out;
  out.sum = vgetq_lane_u64(acc, 0) + vgetq_lane_u64(acc, 1);
  out.count = count;
  return out;
}

}  // namespace

SquaredSum squared_sum_neon(const std::int16_t* q, const std::uint8_t* qmask, const std::int16_t* e,
                            const std::uint8_t* emask, std::size_t blocks) {
  return squared_sum_body(q, qmask, e, emask, blocks, vld1q_u16(kLaneBits));
}

namespace {

// One block of a gapless candidate against the prepared query: |q - e| in
// uint16 (SABD keeps the low 16 bits, and |q - e| <= 65534), the query's
// lane mask on the differences, widening squares (< 2^32), pairwise into
// the uint64 accumulator.
inline uint64x2_t add_block(uint64x2_t sum, int16x8_t q, uint16x8_t mask, const std::int16_t* e) {
  const uint16x8_t d = vandq_u16(vreinterpretq_u16_s16(vabdq_s16(q, vld1q_s16(e))), mask);
  sum = vpadalq_u32(sum, vmull_u16(vget_low_u16(d), vget_low_u16(d)));
  return vpadalq_u32(sum, vmull_high_u16(d, d));
}

}  // namespace

void squared_sums_neon(const CompactTable& table, std::size_t block0, std::size_t blocks, const std::int16_t* q,
                       const std::uint8_t* qmask, SquaredSum* acc) {
  const uint16x8_t lane_bits = vld1q_u16(kLaneBits);
  // The query's side once for all candidates, a chunk of blocks at a time:
  // its values, its lane masks and its count. A candidate without gaps then
  // costs a load, an absolute difference, a mask, two squares and two
  // accumulations per block; one- and two-block queries (the short ones of
  // a hand-held sweep's start) run unrolled with the candidates' pointers
  // stepped, not recomputed.
  constexpr std::size_t kChunk = 32;
  int16x8_t qv[kChunk];
  uint16x8_t mv[kChunk];
  const std::size_t stride = table.padded_elements(), K = table.n_candidates();
  for (std::size_t c0 = 0; c0 < blocks; c0 += kChunk) {
    const std::size_t n = blocks - c0 < kChunk ? blocks - c0 : kChunk;
    std::uint32_t qcount = 0;
    for (std::size_t b = 0; b < n; ++b) {
      const unsigned m = qmask[c0 + b];
      qcount += static_cast<std::uint32_t>(__builtin_popcount(m));
      qv[b] = vld1q_s16(q + (c0 + b) * 8);
      mv[b] = vtstq_u16(vdupq_n_u16(static_cast<std::uint16_t>(m)), lane_bits);
    }
    const std::int16_t* e = table.values(0) + (block0 + c0) * kCompactBlock;
    for (std::size_t k = 0; k < K; ++k, e += stride) {
      if (const std::uint8_t* em = table.validity(k)) {  // gaps in this candidate: the general kernel
        const SquaredSum s = squared_sum_body(q + c0 * 8, qmask + c0, e, em + block0 + c0, n, lane_bits);
        acc[k].sum += s.sum;
        acc[k].count += s.count;
        continue;
      }
      uint64x2_t sum = add_block(vdupq_n_u64(0), qv[0], mv[0], e);
      if (n == 2) {
        sum = add_block(sum, qv[1], mv[1], e + 8);
      } else if (n > 2) {
        for (std::size_t b = 1; b < n; ++b) sum = add_block(sum, qv[b], mv[b], e + b * 8);
      }
      acc[k].sum += vaddvq_u64(sum);
      acc[k].count += qcount;
    }
  }
}

namespace {

// Sums (and nothing else) of Blocks x 8 candidates over the query's valid
// elements in the given block ranges: per element, a broadcast of the query
// value, an absolute difference per 8 candidates (kept in 16 bits), the
// element's validity lanes where some candidate misses it, two widening
// squares and four widening adds into the candidates' uint64 lanes.
// Blocks = 0: the table's slots / 8, in loops.
template <int Blocks>
void element_sums(const ElementMajorTable& em, const BlockRange* ranges, std::size_t n_ranges, const std::int16_t* q,
                  const std::uint8_t* qmask, std::uint64_t* out) {
  constexpr std::size_t kMaxGroups = 32;  // 256 slots
  const std::size_t groups = Blocks > 0 ? static_cast<std::size_t>(Blocks) : em.slots / 8;
  uint64x2_t acc[kMaxGroups * 4];
  for (std::size_t j = 0; j < 4 * groups; ++j) acc[j] = vdupq_n_u64(0);
  for (std::size_t r = 0; r < n_ranges; ++r) {
    for (std::size_t b = ranges[r].block0; b < ranges[r].block0 + ranges[r].blocks; ++b) {
      for (unsigned m = qmask[b]; m != 0; m &= m - 1) {
        const std::size_t e = b * 8 + static_cast<std::size_t>(__builtin_ctz(m));
        const int16x8_t qd = vdupq_n_s16(q[e]);
        const std::int16_t* v = em.values.data() + e * em.slots;
        const std::int32_t gap = em.gap_row[e];
        const std::uint16_t* lanes = gap < 0 ? nullptr : em.gap_lanes.data() + static_cast<std::size_t>(gap) * em.slots;
        for (std::size_t j = 0; j < groups; ++j) {
          uint16x8_t d = vreinterpretq_u16_s16(vabdq_s16(qd, vld1q_s16(v + 8 * j)));  // |q - e| <= 65534
          if (lanes) d = vandq_u16(d, vld1q_u16(lanes + 8 * j));
          const uint32x4_t lo = vmull_u16(vget_low_u16(d), vget_low_u16(d));
          const uint32x4_t hi = vmull_high_u16(d, d);
          acc[4 * j] = vaddw_u32(acc[4 * j], vget_low_u32(lo));
          acc[4 * j + 1] = vaddw_high_u32(acc[4 * j + 1], lo);
          acc[4 * j + 2] = vaddw_u32(acc[4 * j + 2], vget_low_u32(hi));
          acc[4 * j + 3] = vaddw_high_u32(acc[4 * j + 3], hi);
        }
      }
    }
  }
  for (std::size_t j = 0; j < 4 * groups; ++j) vst1q_u64(out + 2 * j, acc[j]);
}

}  // namespace

void squared_sums_elements_neon(const ElementMajorTable& em, const CompactTable& table, const BlockRange* ranges,
                                std::size_t n_ranges, const std::int16_t* q, const std::uint8_t* qmask,
                                SquaredSum* acc) {
  std::uint64_t sums[256];
  switch (em.slots / 8) {
    case 1: element_sums<1>(em, ranges, n_ranges, q, qmask, sums); break;
    case 2: element_sums<2>(em, ranges, n_ranges, q, qmask, sums); break;
    case 3: element_sums<3>(em, ranges, n_ranges, q, qmask, sums); break;
    case 4: element_sums<4>(em, ranges, n_ranges, q, qmask, sums); break;
    default: element_sums<0>(em, ranges, n_ranges, q, qmask, sums);
  }
  // Counts: the query's valid elements, then for the candidates with gaps
  // the elements they miss taken off (a popcount a block).
  std::uint32_t qcount = 0;
  for (std::size_t r = 0; r < n_ranges; ++r) {
    for (std::size_t b = ranges[r].block0; b < ranges[r].block0 + ranges[r].blocks; ++b) {
      qcount += static_cast<std::uint32_t>(__builtin_popcount(qmask[b]));
    }
  }
  for (std::size_t k = 0; k < table.n_candidates(); ++k) {
    acc[k].sum += sums[k];
    acc[k].count += qcount;
  }
  for (const std::uint32_t k : em.gapped) {
    const std::uint8_t* m = table.validity(k);
    for (std::size_t r = 0; r < n_ranges; ++r) {
      for (std::size_t b = ranges[r].block0; b < ranges[r].block0 + ranges[r].blocks; ++b) {
        acc[k].count -= static_cast<std::uint32_t>(__builtin_popcount(qmask[b] & ~m[b] & 0xFFu));
      }
    }
  }
}

}  // namespace tofmat
#endif
