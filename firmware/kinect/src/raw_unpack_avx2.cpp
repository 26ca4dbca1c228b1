// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The AVX2 kernel of the 11-bit unpack (x86-64 hosts whose CPU has AVX2; the
// scalar kernel and the definition in raw_unpack.cpp are what it must equal,
// bit for bit). Compiled with a target attribute, not -mavx2, so the rest of
// the library still runs on any x86-64; unpack_raw_region calls it only when
// the CPU reports AVX2 (cpu_has_avx2, as the fixed-point decode does).
//
// Per stored row (kinect2-protocol.md 2.3): four runs of 128 slots, 176 bytes
// each, slot i of run r being output column 4 i + r. A step takes 16 slots of
// each run (22 bytes: two 11-byte groups of 8, one per 128-bit lane), turns
// the codes into raw values, and interleaves the four runs into 64 columns:
// whole rows, or the steps a column range touches.
#include "tofmat/kinect/raw_unpack.hpp"

#if defined(__x86_64__)
#include <immintrin.h>

#include <cstddef>

#include "tofmat/kinect/constants.hpp"

#define TOFMAT_AVX2 __attribute__((target("avx2"), always_inline)) inline

namespace tofmat::kinect {
namespace {

using namespace unpack_detail;

// The byte shuffle of one group of 8 slots whose 11 bytes start at byte L of
// the low lane (H of the high lane): 32-bit element e gets the four bytes from
// floor(22 e / 8), where the even slot 2 e starts (bit offset s = 0, 6, 4, 2).
// Slots 2 e and 2 e + 1 both lie inside those 32 bits (s + 22 <= 28); the
// last element needs only three bytes (the group ends at byte 10), the fourth
// is zeroed (index bit 7) so nothing past the group is used.
template <int L, int H>
TOFMAT_AVX2 __m256i group_control() {
  return _mm256_setr_epi8(L + 0, L + 1, L + 2, L + 3, L + 2, L + 3, L + 4, L + 5, L + 5, L + 6, L + 7, L + 8, L + 8,
                          L + 9, L + 10, -128, H + 0, H + 1, H + 2, H + 3, H + 2, H + 3, H + 4, H + 5, H + 5, H + 6,
                          H + 7, H + 8, H + 8, H + 9, H + 10, -128);
}

// 16 codes (slot order) in 16-bit lanes from two groups placed by `control`:
// x = element >> s has slot 2 e in bits 0..10 and slot 2 e + 1 in bits
// 11..21; the blend takes the low half of x and the high half of x << 5
// (bits 11..26 of x). Each 16-bit lane holds its code in bits 0..10 and
// whatever followed it above: values16 reads only bits 0..10.
TOFMAT_AVX2 __m256i codes16(__m256i bytes, __m256i control) {
  const __m256i x = _mm256_srlv_epi32(_mm256_shuffle_epi8(bytes, control), _mm256_setr_epi32(0, 6, 4, 2, 0, 6, 4, 2));
  return _mm256_blend_epi16(x, _mm256_slli_epi32(x, 5), 0xAA);
}

// The device table (2.4) computed from the code instead of looked up (AVX2
// has no 16-bit gather). Magnitude code m = c & 1023 in block b = m >> 7:
// steps of 1 below 256, then 2^(b-1), so with t = max(b - 1, 0) the value is
// (m - 128 t) 2^t (for b >= 2: v(128 b) = 2^(b+6), plus (m - 128 b) steps of
// 2^(b-1)). 2^t (t <= 6) comes from a byte table: t sits in each lane's low
// byte, and the high byte's index has bit 7 set, which makes pshufb write 0.
// The code's 11 bits shifted to the top of the lane (h = c << 5) give the
// sign (bit 10, now the lane's sign: _mm256_sign_epi16 negates where h < 0;
// h is 0 only for code 0, whose value 0 it keeps) and the saturation marker
// (code 1024, value 0 so far: h = 0x8000) that becomes 32767.
TOFMAT_AVX2 __m256i values16(__m256i c) {
  const __m256i m = _mm256_and_si256(c, _mm256_set1_epi16(0x3FF));
  const __m256i t = _mm256_subs_epu16(_mm256_srli_epi16(m, 7), _mm256_set1_epi16(1));
  const __m256i base = _mm256_sub_epi16(m, _mm256_slli_epi16(t, 7));
  const __m256i powers = _mm256_setr_epi8(1, 2, 4, 8, 16, 32, 64, 0, 0, 0, 0, 0, 0, 0, 0, 0,  //
                                          1, 2, 4, 8, 16, 32, 64, 0, 0, 0, 0, 0, 0, 0, 0, 0);
  const __m256i scale = _mm256_shuffle_epi8(powers, _mm256_or_si256(t, _mm256_set1_epi16(-32768)));
  const __m256i h = _mm256_slli_epi16(c, 5);
  const __m256i v = _mm256_sign_epi16(_mm256_mullo_epi16(base, scale), h);
  const __m256i saturated = _mm256_cmpeq_epi16(h, _mm256_set1_epi16(-32768));
  return _mm256_or_si256(v, _mm256_srli_epi16(saturated, 1));
}

// Bytes p[0..15] in the low lane and p[11..26] in the high lane: the two
// groups of a 22-byte step, each at lane byte 0. Reads 5 bytes past the step.
TOFMAT_AVX2 __m256i load_step(const std::uint8_t* p) {
  const __m128i lo = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
  const __m128i hi = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + kGroupBytes));
  return _mm256_inserti128_si256(_mm256_castsi128_si256(lo), hi, 1);
}

// Slots 16 k .. 16 k + 15 of runs 0..3 (r0..r3) as columns 64 k .. 64 k + 63:
// column 4 i + r. The in-lane unpacks give, per lane, 2 slots x 4 runs per
// vector; the cross-lane permutes put the slots in column order.
TOFMAT_AVX2 void store_columns(std::int16_t* out, __m256i r0, __m256i r1, __m256i r2, __m256i r3) {
  const __m256i ab_lo = _mm256_unpacklo_epi16(r0, r1),
                ab_hi = _mm256_unpackhi_epi16(r0, r1);  // slots 0-3|8-11, 4-7|12-15
  const __m256i cd_lo = _mm256_unpacklo_epi16(r2, r3), cd_hi = _mm256_unpackhi_epi16(r2, r3);
  const __m256i q0 = _mm256_unpacklo_epi32(ab_lo, cd_lo);  // slots 0, 1 | 8, 9
  const __m256i q1 = _mm256_unpackhi_epi32(ab_lo, cd_lo);  // 2, 3 | 10, 11
  const __m256i q2 = _mm256_unpacklo_epi32(ab_hi, cd_hi);  // 4, 5 | 12, 13
  const __m256i q3 = _mm256_unpackhi_epi32(ab_hi, cd_hi);  // 6, 7 | 14, 15
  auto* o = reinterpret_cast<__m256i*>(out);
  _mm256_storeu_si256(o + 0, _mm256_permute2x128_si256(q0, q1, 0x20));
  _mm256_storeu_si256(o + 1, _mm256_permute2x128_si256(q2, q3, 0x20));
  _mm256_storeu_si256(o + 2, _mm256_permute2x128_si256(q0, q1, 0x31));
  _mm256_storeu_si256(o + 3, _mm256_permute2x128_si256(q2, q3, 0x31));
}

// Columns 64 k .. 64 k + 63: groups 2 k and 2 k + 1 of the four runs. The
// row's last step (run 3, bytes 682..703) ends on the row's last byte: it
// loads the row's last 32 bytes instead (the step at byte 10 of them) and
// takes qwords 1, 2 (bytes 8..23: the first group from lane byte 2) and 2, 3
// (bytes 16..31: the second from lane byte 5).
template <bool Last>
TOFMAT_AVX2 void unpack_step_avx2(const std::uint8_t* row, std::size_t k, std::int16_t* dst) {
  const __m256i control = group_control<0, 0>();
  const std::uint8_t* p = row + k * 2 * kGroupBytes;
  const __m256i r0 = values16(codes16(load_step(p), control));
  const __m256i r1 = values16(codes16(load_step(p + kRunBytes), control));
  const __m256i r2 = values16(codes16(load_step(p + 2 * kRunBytes), control));
  __m256i r3;
  if (Last) {
    const __m256i last = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(row + kRowBytes - 32));
    r3 = values16(codes16(_mm256_permute4x64_epi64(last, 0xE9), group_control<2, 5>()));
  } else {
    r3 = values16(codes16(load_step(p + 3 * kRunBytes), control));
  }
  store_columns(dst, r0, r1, r2, r3);
}

constexpr std::size_t kSteps = kGroupsPerRun / 2;  // 64 columns each

__attribute__((target("avx2"))) void unpack_row_avx2(const std::uint8_t* row, std::int16_t* out) {
  for (std::size_t k = 0; k + 1 < kSteps; ++k) unpack_step_avx2<false>(row, k, out + 2 * kBlockColumns * k);
  unpack_step_avx2<true>(row, kSteps - 1, out + 2 * kBlockColumns * (kSteps - 1));
  out[0] = 0;           // column 0 is slot 0 of run 0
  out[kWidth - 1] = 0;  // column 511 is slot 127 of run 3
}

// One step as a call (for a column range: the row walk of raw_unpack.hpp
// calls it, and that code is not compiled for AVX2, so nothing AVX2 may be
// inlined into it).
__attribute__((target("avx2"))) void unpack_one_step_avx2(const std::uint8_t* row, std::size_t k, std::int16_t* dst) {
  if (k + 1 < kSteps) {
    unpack_step_avx2<false>(row, k, dst);
  } else {
    unpack_step_avx2<true>(row, k, dst);
  }
}

}  // namespace

void unpack_region_avx2(const std::uint8_t* sub_image, std::int16_t* raw, const PixelRegion& region) {
  const bool whole_rows = region.x0 == 0 && region.x1 == kWidth;
  for (int y = region.y0; y < region.y1; ++y) {
    const std::uint8_t* row = sub_image + static_cast<std::size_t>(stored_row_of_output_row(y)) * kRowBytes;
    std::int16_t* out = raw + static_cast<std::size_t>(y) * kWidth;
    if (whole_rows) {
      unpack_row_avx2(row, out);
    } else {
      unpack_row_columns<2 * kBlockColumns>(out, region.x0, region.x1, [&](int k, std::int16_t* dst) {
        unpack_one_step_avx2(row, static_cast<std::size_t>(k), dst);
      });
    }
  }
}

}  // namespace tofmat::kinect

#endif  // __x86_64__
