// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The AVX2 kernel of the fixed-point phase and amplitude (x86-64 hosts whose
// CPU has AVX2; the scalar kernel in fixed_decode.cpp is its definition):
// eight pixels a step, the same integers bit for bit. Compiled with a target
// attribute, not -mavx2, so the rest of the library still runs on any x86-64;
// decode_frame_fixed calls it only when the CPU reports AVX2.
#include "tofmat/core/fixed_decode.hpp"

#if defined(__x86_64__)
#include <immintrin.h>

#include <algorithm>
#include <cstring>
#include <utility>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/raw_lut.hpp"

#define TOFMAT_AVX2 __attribute__((target("avx2"), always_inline)) inline

namespace tofmat {
namespace {

using namespace fixed_decode_detail;

// (v ^ m) - m of the scalar kernel (m = -1 where y < 0) is _mm256_sign_epi32
// with a selector that has y's sign and is never zero: y | 1. Two vectors go
// through the steps together: one step's chain (or, sign, add) is three
// instructions deep, so a single vector would leave the core idle.
template <int K>
TOFMAT_AVX2 void cordic_step(__m256i (&x)[2], __m256i (&y)[2], __m256i (&angle)[2]) {
  const __m256i turn = _mm256_set1_epi32(static_cast<std::int32_t>(kAtanTurns[K]));
  for (int v = 0; v < 2; ++v) {
    const __m256i s = _mm256_or_si256(y[v], _mm256_set1_epi32(1));
    const __m256i xs = K > 0 ? _mm256_srai_epi32(x[v], K) : x[v];
    const __m256i ys = K > 0 ? _mm256_srai_epi32(y[v], K) : y[v];
    x[v] = _mm256_add_epi32(x[v], _mm256_sign_epi32(ys, s));
    y[v] = _mm256_sub_epi32(y[v], _mm256_sign_epi32(xs, s));
    angle[v] = _mm256_add_epi32(angle[v], _mm256_sign_epi32(turn, s));
  }
}

template <int... K>
TOFMAT_AVX2 void cordic(__m256i (&x)[2], __m256i (&y)[2], __m256i (&angle)[2], std::integer_sequence<int, K...>) {
  (cordic_step<K>(x, y, angle), ...);
}

// round(2 a b / 2^32) per 32-bit lane (rounding_doubling_mul_high), b a constant.
TOFMAT_AVX2 __m256i rounding_doubling_mul_high8(__m256i a, std::int32_t b) {
  const __m256i bv = _mm256_set1_epi32(b);
  const __m256i half = _mm256_set1_epi64x(std::int64_t{1} << 30);
  // (a b + 2^30) >> 31 = (2 a b + 2^31) >> 32; the low 32 bits of a logical
  // 64-bit shift are those of the arithmetic one.
  const __m256i even = _mm256_srli_epi64(_mm256_add_epi64(_mm256_mul_epi32(a, bv), half), 31);
  const __m256i odd = _mm256_srli_epi64(_mm256_add_epi64(_mm256_mul_epi32(_mm256_srli_epi64(a, 32), bv), half), 31);
  return _mm256_blend_epi32(even, _mm256_slli_epi64(odd, 32), 0xAA);
}

// The steps before the CORDIC for 8 pixels: saturation flags, the phasor,
// the scaling, the half-plane turn (as the scalar kernel).
struct Prepared {
  __m256i x, y, angle, sh, none;
};

TOFMAT_AVX2 Prepared prepare(const std::int16_t* m0, const std::int16_t* m1, const std::int16_t* m2,
                             std::uint8_t* flags) {
  const __m256i sat = _mm256_set1_epi32(kRawSaturated);
  const __m256i zero = _mm256_setzero_si256();
  const __m256i a0 = _mm256_cvtepi16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(m0)));
  const __m256i a1 = _mm256_cvtepi16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(m1)));
  const __m256i a2 = _mm256_cvtepi16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(m2)));
  const __m256i saturated = _mm256_or_si256(_mm256_or_si256(_mm256_cmpeq_epi32(a0, sat), _mm256_cmpeq_epi32(a1, sat)),
                                            _mm256_cmpeq_epi32(a2, sat));
  if (const int bits = _mm256_movemask_ps(_mm256_castsi256_ps(saturated))) {  // rare: lane by lane
    for (int l = 0; l < 8; ++l) {
      if ((bits >> l) & 1) flags[l] |= kDecodeSaturated;
    }
  }
  Prepared p;
  const __m256i X = _mm256_sub_epi32(_mm256_sub_epi32(_mm256_slli_epi32(a0, 1), a1), a2);
  const __m256i W = _mm256_sub_epi32(a2, a1);
  p.none = _mm256_and_si256(_mm256_cmpeq_epi32(X, zero), _mm256_cmpeq_epi32(W, zero));
  // sh = max(0, clz(mx) - 4) with mx = max(|X|, |W|) | 1 < 2^18: its
  // conversion to float is exact, so the exponent field is floor(log2 mx)
  // and clz = 31 - floor(log2 mx); sh = 27 - floor(log2 mx) >= 10.
  const __m256i mx = _mm256_or_si256(_mm256_max_epi32(_mm256_abs_epi32(X), _mm256_abs_epi32(W)), _mm256_set1_epi32(1));
  const __m256i e =
      _mm256_sub_epi32(_mm256_srli_epi32(_mm256_castps_si256(_mm256_cvtepi32_ps(mx)), 23), _mm256_set1_epi32(127));
  p.sh = _mm256_sub_epi32(_mm256_set1_epi32(27), e);
  __m256i x = _mm256_sllv_epi32(X, p.sh);
  __m256i y = _mm256_slli_epi32(rounding_doubling_mul_high8(_mm256_sllv_epi32(W, p.sh), kHalfSqrt3Q31), 1);
  const __m256i left = _mm256_cmpgt_epi32(zero, x);
  p.x = _mm256_abs_epi32(x);
  p.y = _mm256_sub_epi32(_mm256_xor_si256(y, left), left);
  p.angle = _mm256_and_si256(left, _mm256_set1_epi32(static_cast<std::int32_t>(0x80000000u)));
  return p;
}

// phase = angle - p0, amplitude_q8 = x * kAmpScale >> (25 + sh) in 64-bit lanes (x >= 0).
TOFMAT_AVX2 void finish(const Prepared& p, __m256i x, __m256i angle, const std::uint32_t* p0, std::uint32_t* phase,
                        std::uint32_t* amp_q8) {
  const __m256i ph = _mm256_sub_epi32(angle, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p0)));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(phase), _mm256_andnot_si256(p.none, ph));
  const __m256i scale = _mm256_set1_epi32(static_cast<std::int32_t>(kAmpScale));
  const __m256i rs = _mm256_add_epi32(p.sh, _mm256_set1_epi32(kAmpScaleBits));
  const __m256i even =
      _mm256_srlv_epi64(_mm256_mul_epu32(x, scale), _mm256_and_si256(rs, _mm256_set1_epi64x(0xFFFFFFFF)));
  const __m256i odd = _mm256_srlv_epi64(_mm256_mul_epu32(_mm256_srli_epi64(x, 32), scale), _mm256_srli_epi64(rs, 32));
  const __m256i amp = _mm256_blend_epi32(even, _mm256_slli_epi64(odd, 32), 0xAA);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(amp_q8), _mm256_andnot_si256(p.none, amp));
}

}  // namespace

__attribute__((target("avx2"))) void phase_amplitude_avx2(const std::int16_t* m0, const std::int16_t* m1,
                                                          const std::int16_t* m2, const std::uint32_t* p0,
                                                          std::size_t n, std::uint32_t* phase, std::uint32_t* amp_q8,
                                                          std::uint8_t* flags) {
  const __m256 turns_per_rad = _mm256_set1_ps(kTurnsPerRadF), third = _mm256_set1_ps(kThirdF),
               half = _mm256_set1_ps(0.5f);
  std::size_t i = 0;
  for (; i + 16 <= n; i += 16) {
    const Prepared a = prepare(m0 + i, m1 + i, m2 + i, flags + i);
    const Prepared b = prepare(m0 + i + 8, m1 + i + 8, m2 + i + 8, flags + i + 8);
    __m256i x[2] = {a.x, b.x}, y[2] = {a.y, b.y}, angle[2] = {a.angle, b.angle};
    cordic(x, y, angle, std::make_integer_sequence<int, kCordicSteps>{});
    for (int v = 0; v < 2; ++v) {  // the residual angle and the magnitude, as the scalar kernel
      const __m256 xf = _mm256_cvtepi32_ps(x[v]);
      const __m256 t = _mm256_div_ps(_mm256_cvtepi32_ps(y[v]), xf);
      const __m256 t2 = _mm256_mul_ps(t, t);
      const __m256 r = _mm256_sub_ps(t, _mm256_mul_ps(_mm256_mul_ps(t, t2), third));
      angle[v] = _mm256_add_epi32(angle[v], _mm256_cvtps_epi32(_mm256_mul_ps(r, turns_per_rad)));
      x[v] = _mm256_add_epi32(x[v], _mm256_cvtps_epi32(_mm256_mul_ps(_mm256_mul_ps(xf, t2), half)));
    }
    finish(a, x[0], angle[0], p0 + i, phase + i, amp_q8 + i);
    finish(b, x[1], angle[1], p0 + i + 8, phase + i + 8, amp_q8 + i + 8);
  }
  if (i < n) phase_amplitude_scalar(m0 + i, m1 + i, m2 + i, p0 + i, n - i, phase + i, amp_q8 + i, flags + i);
}

namespace {

// n / (R << 16) = (n >> 16) / R for n >= 0, and (n >> 16) < 2^14 here
// (kDiv80, kDiv120): the unwrap's divisions without a divide.
TOFMAT_AVX2 __m256i div_range_q16(__m256i n, DivisionMagic d) {
  return _mm256_srl_epi32(_mm256_mullo_epi32(_mm256_srli_epi32(n, 16), _mm256_set1_epi32(d.magic)),
                          _mm_cvtsi32_si128(d.shift));
}

// a >= b for unsigned 32-bit lanes.
TOFMAT_AVX2 __m256i ge_u32(__m256i a, __m256i b) { return _mm256_cmpeq_epi32(_mm256_max_epu32(a, b), a); }

// An int64 gap threshold as int32: gaps are < 2^31, so a threshold beyond is never exceeded; -1 always is.
std::int32_t gap32(std::int64_t th) { return static_cast<std::int32_t>(std::min<std::int64_t>(th, 0x7FFFFFFF)); }

// 10 a + 2 b + 15 c with shifts: 8a + 2a + 2b + 16c - c.
TOFMAT_AVX2 __m256i weighted_sum(__m256i a, __m256i b, __m256i c) {
  const __m256i a10 = _mm256_add_epi32(_mm256_slli_epi32(a, 3), _mm256_slli_epi32(a, 1));
  const __m256i c15 = _mm256_sub_epi32(_mm256_slli_epi32(c, 4), c);
  return _mm256_add_epi32(_mm256_add_epi32(a10, _mm256_slli_epi32(b, 1)), c15);
}

TOFMAT_AVX2 __m256i load(const void* p) { return _mm256_loadu_si256(static_cast<const __m256i*>(p)); }
TOFMAT_AVX2 void store(void* p, __m256i v) { _mm256_storeu_si256(static_cast<__m256i*>(p), v); }

}  // namespace

__attribute__((target("avx2"))) void finish_pixels_avx2(const FixedPlanes& p, std::size_t n,
                                                        const FixedThresholds& th) {
  const __m256i invalid = _mm256_set1_epi32(kFixedInvalid);
  const __m256i th_amp = _mm256_set1_epi32(static_cast<std::int32_t>(th.amp));
  const __m256i th_mean = _mm256_set1_epi32(static_cast<std::int32_t>(th.mean_sum));
  const __m256i th_unwrap = _mm256_set1_epi32(static_cast<std::int32_t>(th.unwrap_amp));
  const __m256i th_gap1 = _mm256_set1_epi32(gap32(th.gap_16_80)), th_gap2 = _mm256_set1_epi32(gap32(th.gap_80_120));
  const __m256i R80 = _mm256_set1_epi32(1875 << 16), R120 = _mm256_set1_epi32(1250 << 16);
  const __m256i low8 = _mm256_set1_epi32(0xFF);
  const __m256i dark_flag = _mm256_set1_epi32(kDecodeDark), unwrap_flag = _mm256_set1_epi32(kDecodeUnwrap);
  // the low byte of each 32-bit lane, to the first four bytes of each half
  const __m256i bytes = _mm256_setr_epi8(0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1,  //
                                         0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1);
  constexpr std::int32_t kRange[3] = {1875, 9375, 1250};
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    __m256i d[3], a[3];
    __m256i dark = _mm256_setzero_si256();
    for (std::size_t g = 0; g < 3; ++g) {
      // (phase * R) >> 16 = (phase >> 16) R + ((phase & 0xFFFF) R >> 16), each
      // product < 2^30; the second is an unsigned 16-bit multiply-high with R
      // in the low half of each lane and 0 in the high half (which then gives 0).
      const __m256i ph = load(p.phase[g] + i);
      d[g] = _mm256_add_epi32(_mm256_mullo_epi32(_mm256_srli_epi32(ph, 16), _mm256_set1_epi32(kRange[g])),
                              _mm256_mulhi_epu16(ph, _mm256_set1_epi32(kRange[g])));
      a[g] = load(p.amp[g] + i);
      dark = _mm256_or_si256(dark, _mm256_xor_si256(ge_u32(a[g], th_amp), _mm256_set1_epi32(-1)));
    }
    // amplitudes are below 2^23 (docs/numerics.md): their sum fits 32 bits
    const __m256i sum = _mm256_add_epi32(_mm256_add_epi32(a[0], a[1]), a[2]);
    dark = _mm256_or_si256(dark, _mm256_xor_si256(ge_u32(sum, th_mean), _mm256_set1_epi32(-1)));
    __m256i flags = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p.flags + i)));
    flags = _mm256_or_si256(flags, _mm256_and_si256(dark, dark_flag));
    const __m256i bad = _mm256_xor_si256(_mm256_cmpeq_epi32(flags, _mm256_setzero_si256()), _mm256_set1_epi32(-1));
    // Unwrap (as the scalar code; k80 + 1 and k120 + 2 are the quotients).
    const __m256i D16 = d[kGroup16];
    const __m256i n1 =
        _mm256_add_epi32(_mm256_sub_epi32(D16, d[kGroup80]), _mm256_set1_epi32((1875 << 16) / 2 + (1875 << 16)));
    const __m256i k80 = _mm256_sub_epi32(div_range_q16(n1, kDiv80), _mm256_set1_epi32(1));
    const __m256i D80 = _mm256_add_epi32(d[kGroup80], _mm256_mullo_epi32(k80, R80));
    const __m256i n2 =
        _mm256_add_epi32(_mm256_sub_epi32(D80, d[kGroup120]), _mm256_set1_epi32((1250 << 16) / 2 + 2 * (1250 << 16)));
    const __m256i k120 = _mm256_sub_epi32(div_range_q16(n2, kDiv120), _mm256_set1_epi32(2));
    const __m256i D120 = _mm256_add_epi32(d[kGroup120], _mm256_mullo_epi32(k120, R120));
    const __m256i gap1 = _mm256_abs_epi32(_mm256_sub_epi32(D80, D16));
    const __m256i gap2 = _mm256_abs_epi32(_mm256_sub_epi32(D120, D80));
    const __m256i unwrap_bad = _mm256_andnot_si256(
        bad, _mm256_or_si256(_mm256_xor_si256(ge_u32(a[kGroup16], th_unwrap), _mm256_set1_epi32(-1)),
                             _mm256_or_si256(_mm256_cmpgt_epi32(gap1, th_gap1), _mm256_cmpgt_epi32(gap2, th_gap2))));
    flags = _mm256_blendv_epi8(flags, unwrap_flag, unwrap_bad);
    const __m256i off = _mm256_or_si256(bad, unwrap_bad);
    for (std::size_t g = 0; g < 3; ++g) store(p.depth[g] + i, _mm256_blendv_epi8(d[g], invalid, off));
    // num8 = (10 D80 + 2 D16 + 15 D120) >> 8 exactly in 32 bits: D = 256 (D >> 8) + (D & 255).
    const __m256i hi = weighted_sum(_mm256_srai_epi32(D80, 8), _mm256_srai_epi32(D16, 8), _mm256_srai_epi32(D120, 8));
    const __m256i lo =
        weighted_sum(_mm256_and_si256(D80, low8), _mm256_and_si256(D16, low8), _mm256_and_si256(D120, low8));
    const __m256i num8 = _mm256_add_epi32(hi, _mm256_srli_epi32(lo, 8));
    // (num8 * ceil(2^32 / 27)) >> 32: the high half of a signed 64-bit product.
    const __m256i inv27 = _mm256_set1_epi32(159072863);
    const __m256i even = _mm256_srli_epi64(_mm256_mul_epi32(num8, inv27), 32);
    const __m256i odd = _mm256_mul_epi32(_mm256_srli_epi64(num8, 32), inv27);
    const __m256i combined = _mm256_blend_epi32(even, odd, 0xAA);
    store(p.combined + i, _mm256_blendv_epi8(combined, invalid, off));
    store(p.features[0] + i, _mm256_blendv_epi8(_mm256_sub_epi32(d[kGroup16], d[kGroup120]), invalid, off));
    store(p.features[1] + i, _mm256_blendv_epi8(_mm256_sub_epi32(d[kGroup80], d[kGroup120]), invalid, off));
    const __m256i fb = _mm256_shuffle_epi8(flags, bytes);
    const auto f_lo = static_cast<std::uint32_t>(_mm256_extract_epi32(fb, 0));
    const auto f_hi = static_cast<std::uint32_t>(_mm256_extract_epi32(fb, 4));
    std::memcpy(p.flags + i, &f_lo, 4);
    std::memcpy(p.flags + i + 4, &f_hi, 4);
  }
  if (i < n) finish_pixels_scalar(planes_from(p, i), n - i, th);  // the tail
}

}  // namespace tofmat
#endif
