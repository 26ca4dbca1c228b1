// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The NEON kernel of the per-pixel classification (pixel_classifier.hpp; the
// scalar kernel is its definition; aarch64 only): per pixel, four candidates
// an instruction: saturating int16 differences of the packed value pairs,
// widening squares, pairwise sums; the least sum by a min tree and vminvq,
// its lowest rank by selecting each slot's rank where it holds the least.
#include "tofmat/core/pixel_classifier.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>

#include <array>

namespace tofmat {
namespace {

constexpr std::size_t kMaxSlots = 256;

// s for the four slots at `s` (each a packed pair): (d0^2 + d1^2) << doubled
// | absent (the absent mask only at bins that need it: elsewhere it is 0).
template <bool OneValid, bool Absent>
inline int32x4_t sums4(const PixelClassifier::Layout& t, std::size_t s, int16x8_t q) {
  const int16x8_t e = vreinterpretq_s16_s32(vld1q_s32(t.pairs.data() + s));
  int16x8_t d = vmaxq_s16(vqsubq_s16(q, e), vdupq_n_s16(-32767));  // clamp(q - e, +-32767)
  if constexpr (OneValid) d = vandq_s16(d, vreinterpretq_s16_s32(vld1q_s32(t.elem_mask.data() + s)));
  const int32x4_t lo = vmull_s16(vget_low_s16(d), vget_low_s16(d));  // d0^2 d1^2 of slots 0, 1
  const int32x4_t hi = vmull_high_s16(d, d);                         // of slots 2, 3
  int32x4_t sum = vpaddq_s32(lo, hi);                                // <= 2 * 32767^2 < 2^31
  if constexpr (OneValid) sum = vshlq_s32(sum, vld1q_s32(t.doubled.data() + s));
  if constexpr (Absent) sum = vorrq_s32(sum, vld1q_s32(t.absent.data() + s));
  return sum;
}

// Quads: the slots / 4 of the table when known at compile time (the loops
// unroll and the sums stay in registers), 0 for any.
template <bool OneValid, std::size_t Quads>
std::size_t classify(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q, std::size_t n,
                     std::uint8_t* labels) {
  const std::size_t quads = Quads != 0 ? Quads : t.slots / 4;
  // Each slot's rank (the inverse of slot_of), 255 for none: the label of a
  // slot holding the least sum, the lowest of them by vminvq.
  std::array<std::uint8_t, kMaxSlots> rank_of{};
  for (std::size_t r = 0; r < t.slots; ++r) rank_of[t.slot_of[r]] = static_cast<std::uint8_t>(r);
  std::size_t classified = 0;
  int32x4_t s[Quads != 0 ? Quads : kMaxSlots / 4];
  for (std::size_t i = 0; i < n; ++i) {
    labels[i] = PixelClassifier::kUnclassified;
    if (bin[i] < 0) continue;
    const int16x8_t qv = vreinterpretq_s16_s32(vdupq_n_s32(q[i]));
    const std::size_t base = static_cast<std::size_t>(bin[i]) * t.slots;
    int32x4_t m = vdupq_n_s32(0x7FFFFFFF);
    if (t.needs_absent[static_cast<std::size_t>(bin[i])]) {
      for (std::size_t k = 0; k < quads; ++k) {
        s[k] = sums4<OneValid, true>(t, base + 4 * k, qv);
        m = vminq_s32(m, s[k]);
      }
    } else {
      for (std::size_t k = 0; k < quads; ++k) {
        s[k] = sums4<OneValid, false>(t, base + 4 * k, qv);
        m = vminq_s32(m, s[k]);
      }
    }
    const std::int32_t least = vminvq_s32(m);
    if (least == 0x7FFFFFFF) continue;  // no candidate has a value here
    const int32x4_t lv = vdupq_n_s32(least);
    std::uint8_t label = 255;
    for (std::size_t k = 0; k < quads; k += 4) {  // sixteen slots at a time (slots are a multiple of 8)
      const uint16x8_t a = vcombine_u16(vmovn_u32(vceqq_s32(s[k], lv)), vmovn_u32(vceqq_s32(s[k + 1], lv)));
      const uint16x8_t b = k + 2 < quads
                               ? vcombine_u16(vmovn_u32(vceqq_s32(s[k + 2], lv)), vmovn_u32(vceqq_s32(s[k + 3], lv)))
                               : vdupq_n_u16(0);
      const uint8x16_t hit = vcombine_u8(vmovn_u16(a), vmovn_u16(b));
      const uint8x16_t ranks = vld1q_u8(rank_of.data() + 4 * k);
      const std::uint8_t r = vminvq_u8(vbslq_u8(hit, ranks, vdupq_n_u8(255)));
      label = r < label ? r : label;
    }
    labels[i] = label;
    ++classified;
  }
  return classified;
}

template <bool OneValid>
std::size_t classify_quads(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q,
                           std::size_t n, std::uint8_t* labels) {
  switch (t.slots / 4) {  // up to 32 candidates unrolled
    case 2: return classify<OneValid, 2>(t, bin, q, n, labels);
    case 4: return classify<OneValid, 4>(t, bin, q, n, labels);
    case 6: return classify<OneValid, 6>(t, bin, q, n, labels);
    case 8: return classify<OneValid, 8>(t, bin, q, n, labels);
    default: return classify<OneValid, 0>(t, bin, q, n, labels);
  }
}

}  // namespace

std::size_t classify_pixels_neon(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q,
                                 std::size_t n, std::uint8_t* labels) {
  return t.one_valid ? classify_quads<true>(t, bin, q, n, labels) : classify_quads<false>(t, bin, q, n, labels);
}

void quantise_features_neon(const std::int32_t* f0, const std::int32_t* f1, std::size_t n, int shift, std::int32_t* q) {
  const int32x4_t lim = vdupq_n_s32(std::int32_t{1} << 30), nlim = vdupq_n_s32(-(std::int32_t{1} << 30));
  const int32x4_t half = vdupq_n_s32(std::int32_t{1} << (shift - 1)), rs = vdupq_n_s32(-shift);
  const int32x4_t hi = vdupq_n_s32(32767), lo = vdupq_n_s32(-32767);
  const auto steps = [&](const std::int32_t* f) {
    const int32x4_t v = vaddq_s32(vmaxq_s32(vminq_s32(vld1q_s32(f), lim), nlim), half);
    return vmaxq_s32(vminq_s32(vshlq_s32(v, rs), hi), lo);  // (arithmetic shift right)
  };
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    const int32x4_t a = steps(f0 + i), b = steps(f1 + i);
    const int32x4_t packed = vorrq_s32(vandq_s32(a, vdupq_n_s32(0xFFFF)), vshlq_n_s32(b, 16));
    vst1q_s32(q + i, packed);
  }
  if (i < n) quantise_features_scalar(f0 + i, f1 + i, n - i, shift, q + i);
}

}  // namespace tofmat
#endif
