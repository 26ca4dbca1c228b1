// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The AVX2 kernel of the per-pixel classification (pixel_classifier.hpp; the
// scalar kernel is its definition): per pixel, eight candidates an
// instruction: saturating int16 differences of the packed value pairs, their
// squares summed in pairs by one multiply-add, the least sum and its lowest
// index by a min tree and a compare mask. Compiled with a target attribute;
// called only when the CPU reports AVX2.
#include "tofmat/core/pixel_classifier.hpp"

#if defined(__x86_64__)
#include <immintrin.h>

namespace tofmat {
namespace {

#define TOFMAT_AVX2 __attribute__((target("avx2,bmi"), always_inline)) inline

// The layout's arrays as plain pointers: the labels written through a
// uint8_t* may alias anything, so members read through `t` would be reloaded
// for every pixel.
struct Arrays {
  const std::int32_t* pairs;
  const std::int32_t* elem_mask;
  const std::int32_t* doubled;
  const std::int32_t* absent;
};

// s = (d0^2 + d1^2) << doubled | absent for 8 slots, d = clamp(q - e, +-32767).
template <bool OneValid, bool Absent>
TOFMAT_AVX2 __m256i sums8(const Arrays& t, std::size_t s, __m256i q) {
  const __m256i e = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(t.pairs + s));
  // subs saturates to [-32768, 32767]; the max takes -32768 to -32767 (as
  // the scalar clamp), so that no square pair reaches 2^31.
  __m256i d = _mm256_max_epi16(_mm256_subs_epi16(q, e), _mm256_set1_epi16(-32767));
  if constexpr (OneValid)
    d = _mm256_and_si256(d, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(t.elem_mask + s)));
  __m256i sum = _mm256_madd_epi16(d, d);
  if constexpr (OneValid)
    sum = _mm256_sllv_epi32(sum, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(t.doubled + s)));
  if constexpr (Absent) sum = _mm256_or_si256(sum, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(t.absent + s)));
  return sum;
}

// Broadcast of the least of eight lanes.
TOFMAT_AVX2 __m256i hmin(__m256i v) {
  v = _mm256_min_epi32(v, _mm256_permute2x128_si256(v, v, 0x01));
  v = _mm256_min_epi32(v, _mm256_shuffle_epi32(v, 0x4E));
  return _mm256_min_epi32(v, _mm256_shuffle_epi32(v, 0xB1));
}

// The label of one pixel (kUnclassified if no slot holds values: only
// possible where the bin has absent slots). Blocks > 0: that many blocks of
// eight, unrolled; 0: `blocks` of them in a loop.
template <int Blocks, bool OneValid, bool Absent>
TOFMAT_AVX2 std::uint8_t label_of(const Arrays& t, std::size_t base, std::size_t blocks, __m256i q) {
  constexpr std::size_t kMaxBlocks = 32;  // 256 slots
  constexpr std::size_t B = PixelClassifier::kSlotBlock;
  __m256i s[kMaxBlocks];
  __m256i m = sums8<OneValid, Absent>(t, base, q);
  s[0] = m;
  for (std::size_t b = 1; b < (Blocks > 0 ? static_cast<std::size_t>(Blocks) : blocks); ++b) {
    s[b] = sums8<OneValid, Absent>(t, base + b * B, q);
    m = _mm256_min_epi32(m, s[b]);
  }
  const __m256i least = hmin(m);
  if constexpr (Absent) {
    if (_mm256_cvtsi256_si32(least) == 0x7FFFFFFF) return PixelClassifier::kUnclassified;
  }
  if constexpr (Blocks == 4) {
    // The four masks packed to bytes: bit j of the movemask is rank j (the
    // layout's slot_of), so the lowest set bit is the label.
    const __m256i p01 = _mm256_packs_epi32(_mm256_cmpeq_epi32(s[0], least), _mm256_cmpeq_epi32(s[1], least));
    const __m256i p23 = _mm256_packs_epi32(_mm256_cmpeq_epi32(s[2], least), _mm256_cmpeq_epi32(s[3], least));
    const auto hits = static_cast<std::uint32_t>(_mm256_movemask_epi8(_mm256_packs_epi16(p01, p23)));
    return static_cast<std::uint8_t>(__builtin_ctz(hits));
  } else if constexpr (Blocks > 0 && Blocks < 4) {  // one mask of the lanes holding the least: its lowest bit
    std::uint32_t hits = 0;
    for (std::size_t b = 0; b < static_cast<std::size_t>(Blocks); ++b) {
      hits |= static_cast<std::uint32_t>(_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(s[b], least))))
              << (8 * b);
    }
    return static_cast<std::uint8_t>(__builtin_ctz(hits));
  } else {
    for (std::size_t b = 0;; ++b) {  // the first block holding the least: its lowest lane
      const int hit = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(s[b], least)));
      if (hit != 0)
        return static_cast<std::uint8_t>(b * B + static_cast<std::size_t>(__builtin_ctz(static_cast<unsigned>(hit))));
    }
  }
}

template <int Blocks, bool OneValid>
__attribute__((target("avx2,bmi"))) std::size_t classify_pixels_avx2_t(const PixelClassifier::Layout& layout,
                                                                       const std::int32_t* bin, const std::int32_t* q,
                                                                       std::size_t n, std::uint8_t* labels) {
  const Arrays t{layout.pairs.data(), layout.elem_mask.data(), layout.doubled.data(), layout.absent.data()};
  const std::uint8_t* needs_absent = layout.needs_absent.data();
  const std::size_t slots = layout.slots, blocks = slots / PixelClassifier::kSlotBlock;
  for (std::size_t i = 0; i < n; ++i) {
    std::uint8_t label = PixelClassifier::kUnclassified;
    if (bin[i] >= 0) {
      const auto b = static_cast<std::size_t>(bin[i]);
      const __m256i qv = _mm256_set1_epi32(q[i]);
      label = needs_absent[b] ? label_of<Blocks, OneValid, true>(t, b * slots, blocks, qv)
                              : label_of<Blocks, OneValid, false>(t, b * slots, blocks, qv);
    }
    labels[i] = label;
  }
  // Counted afterwards: a counter in the loop above ends up in memory (the
  // loop keeps every vector register busy), a dependency from pixel to pixel.
  std::size_t classified = 0;
  for (std::size_t i = 0; i < n; ++i) classified += labels[i] != PixelClassifier::kUnclassified;
  return classified;
}

template <bool OneValid>
std::size_t dispatch_blocks(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q,
                            std::size_t n, std::uint8_t* labels) {
  switch (t.slots / PixelClassifier::kSlotBlock) {
    case 1: return classify_pixels_avx2_t<1, OneValid>(t, bin, q, n, labels);
    case 2: return classify_pixels_avx2_t<2, OneValid>(t, bin, q, n, labels);
    case 3: return classify_pixels_avx2_t<3, OneValid>(t, bin, q, n, labels);
    case 4: return classify_pixels_avx2_t<4, OneValid>(t, bin, q, n, labels);
    default: return classify_pixels_avx2_t<0, OneValid>(t, bin, q, n, labels);
  }
}

}  // namespace

__attribute__((target("avx2"))) void quantise_features_avx2(const std::int32_t* f0, const std::int32_t* f1,
                                                            std::size_t n, int shift, std::int32_t* q) {
  const __m256i lim = _mm256_set1_epi32(std::int32_t{1} << 30), nlim = _mm256_set1_epi32(-(std::int32_t{1} << 30));
  const __m256i half = _mm256_set1_epi32(std::int32_t{1} << (shift - 1));
  const __m256i hi = _mm256_set1_epi32(32767), lo = _mm256_set1_epi32(-32767);
  const __m128i sh = _mm_cvtsi32_si128(shift);
  const auto steps = [&](const std::int32_t* f) __attribute__((target("avx2"))) {
    __m256i v = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(f));
    v = _mm256_add_epi32(_mm256_max_epi32(_mm256_min_epi32(v, lim), nlim), half);
    return _mm256_max_epi32(_mm256_min_epi32(_mm256_sra_epi32(v, sh), hi), lo);
  };
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256i a = steps(f0 + i), b = steps(f1 + i);
    const __m256i packed = _mm256_or_si256(_mm256_and_si256(a, _mm256_set1_epi32(0xFFFF)), _mm256_slli_epi32(b, 16));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(q + i), packed);
  }
  if (i < n) quantise_features_scalar(f0 + i, f1 + i, n - i, shift, q + i);
}

std::size_t classify_pixels_avx2(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q,
                                 std::size_t n, std::uint8_t* labels) {
  return t.one_valid ? dispatch_blocks<true>(t, bin, q, n, labels) : dispatch_blocks<false>(t, bin, q, n, labels);
}

}  // namespace tofmat
#endif
