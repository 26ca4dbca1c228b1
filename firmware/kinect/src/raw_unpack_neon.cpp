// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The NEON kernel of the 11-bit unpack (aarch64 only; the scalar kernel and
// the definition in raw_unpack.cpp are what it must equal, bit for bit).
//
// Per stored row (kinect2-protocol.md 2.3): four runs of 128 slots, 176 bytes
// each, slot i of run r being output column 4 i + r. A step takes one 11-byte
// group (8 slots) of each run, turns the codes into raw values, and stores the
// four runs interleaved into 32 columns with one ST4: whole rows, or the
// blocks of 32 columns a column range touches.
#include "tofmat/kinect/raw_unpack.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>

#include <cstddef>

#include "tofmat/kinect/constants.hpp"

namespace tofmat::kinect {
namespace {

using namespace unpack_detail;

// TBL indices for a group whose 11 bytes start at register byte 0: 32-bit
// element e gets the four bytes from floor(22 e / 8), where the even slot 2 e
// starts (bit offset s = 0, 6, 4, 2); slots 2 e and 2 e + 1 both lie inside
// those 32 bits (s + 22 <= 28). The last element needs three bytes (the group
// ends at byte 10); index 255 is out of range, so TBL writes 0.
alignas(16) constexpr std::uint8_t kControl[16] = {0, 1, 2, 3, 2, 3, 4, 5, 5, 6, 7, 8, 8, 9, 10, 255};
// The same for the row's last group read from the row's last 16 bytes (the
// group at register byte 5).
alignas(16) constexpr std::uint8_t kControlLast[16] = {5, 6, 7, 8, 7, 8, 9, 10, 10, 11, 12, 13, 13, 14, 15, 255};
// Right shifts (negative USHL counts) bringing slot 2 e to bit 0, and slot 2 e + 1.
alignas(16) constexpr std::int32_t kShiftEven[4] = {0, -6, -4, -2};
alignas(16) constexpr std::int32_t kShiftOdd[4] = {-11, -17, -15, -13};

// Loaded once per call.
struct Constants {
  uint8x16_t control, control_last;
  int32x4_t shift_even, shift_odd;
  uint16x8_t magnitude_mask;
};

// 8 codes (slot order) of one group: the low 16 bits of each even-shifted
// element hold slot 2 e, those of each odd-shifted element slot 2 e + 1; TRN1
// pairs them lane by lane. Each lane holds its code in bits 0..10 and whatever
// followed it above: values8 reads only bits 0..10.
inline uint16x8_t codes8(uint8x16_t bytes, uint8x16_t control, const Constants& k) {
  const uint32x4_t e = vreinterpretq_u32_u8(vqtbl1q_u8(bytes, control));
  const uint16x8_t even = vreinterpretq_u16_u32(vshlq_u32(e, k.shift_even));
  const uint16x8_t odd = vreinterpretq_u16_u32(vshlq_u32(e, k.shift_odd));
  return vtrn1q_u16(even, odd);
}

// The device table (2.4) computed from the code: magnitude code m = c & 1023
// in block b = m >> 7 has steps of 1 below 256, then 2^(b-1), so with
// t = max(b - 1, 0) the value is (m - 128 t) << t (for b >= 2:
// v(128 b) = 2^(b+6), plus (m - 128 b) steps of 2^(b-1)). The code's 11 bits
// at the top of the lane (h = c << 5) give the sign (bit 10: (v ^ s) - s with
// s = h >> 15, arithmetic) and the saturation marker (code 1024, value 0 so
// far: h = 0x8000), to which half the all-ones mask, 32767, is added.
// (EOR/SUB and an accumulate rather than BSL selects, which overwrite an
// input: fewer register copies per group.)
inline int16x8_t values8(uint16x8_t c, const Constants& k) {
  const int16x8_t h = vreinterpretq_s16_u16(vshlq_n_u16(c, 5));
  const uint16x8_t m = vandq_u16(c, k.magnitude_mask);
  const uint16x8_t t = vqsubq_u16(vshrq_n_u16(m, 7), vdupq_n_u16(1));
  const int16x8_t v = vreinterpretq_s16_u16(vshlq_u16(vmlsq_n_u16(m, t, 128), vreinterpretq_s16_u16(t)));
  const int16x8_t s = vshrq_n_s16(h, 15);
  const int16x8_t signed_v = vsubq_s16(veorq_s16(v, s), s);
  const uint16x8_t saturated = vceqq_s16(h, vdupq_n_s16(-32768));
  return vreinterpretq_s16_u16(vsraq_n_u16(vreinterpretq_u16_s16(signed_v), saturated, 1));
}

inline int16x8_t group_values(const std::uint8_t* p, const Constants& k) {
  return values8(codes8(vld1q_u8(p), k.control, k), k);  // reads 5 bytes past the group
}

// Columns 32 b .. 32 b + 31: group b of the four runs, interleaved by one
// ST4 (column 4 i + r). The row's last group, that of run 3 in block 15
// (bytes 693..703), ends on the row's last byte: a 16-byte load from it would
// read past the row, so the row's last 16 bytes are loaded instead (the group
// at register byte 5).
template <bool Last>
inline void unpack_block_neon(const std::uint8_t* row, std::size_t b, std::int16_t* dst, const Constants& k) {
  const std::uint8_t* p = row + b * kGroupBytes;
  int16x8x4_t r;
  r.val[0] = group_values(p, k);
  r.val[1] = group_values(p + kRunBytes, k);
  r.val[2] = group_values(p + 2 * kRunBytes, k);
  r.val[3] =
      Last ? values8(codes8(vld1q_u8(row + kRowBytes - 16), k.control_last, k), k) : group_values(p + 3 * kRunBytes, k);
  vst4q_s16(dst, r);
}

void unpack_row_neon(const std::uint8_t* row, std::int16_t* out, const Constants& k) {
  for (std::size_t b = 0; b + 1 < kGroupsPerRun; ++b) unpack_block_neon<false>(row, b, out + kBlockColumns * b, k);
  unpack_block_neon<true>(row, kGroupsPerRun - 1, out + kBlockColumns * (kGroupsPerRun - 1), k);
  out[0] = 0;           // column 0 is slot 0 of run 0
  out[kWidth - 1] = 0;  // column 511 is slot 127 of run 3
}

}  // namespace

void unpack_region_neon(const std::uint8_t* sub_image, std::int16_t* raw, const PixelRegion& region) {
  // The magnitude mask is hidden from the optimiser (an empty asm that "may
  // change" it): as a known constant GCC uses BIC with an immediate, which
  // overwrites its input, and the code is needed twice, so every group would
  // pay a register copy (12 % more instructions, counted under qemu).
  uint16x8_t mask = vdupq_n_u16(0x3FF);
  __asm__("" : "+w"(mask));
  const Constants k{vld1q_u8(kControl), vld1q_u8(kControlLast), vld1q_s32(kShiftEven), vld1q_s32(kShiftOdd), mask};
  const bool whole_rows = region.x0 == 0 && region.x1 == kWidth;
  for (int y = region.y0; y < region.y1; ++y) {
    const std::uint8_t* row = sub_image + static_cast<std::size_t>(stored_row_of_output_row(y)) * kRowBytes;
    std::int16_t* out = raw + static_cast<std::size_t>(y) * kWidth;
    if (whole_rows) {
      unpack_row_neon(row, out, k);
    } else {
      unpack_row_columns<kBlockColumns>(out, region.x0, region.x1, [&](int b, std::int16_t* dst) {
        const auto g = static_cast<std::size_t>(b);
        if (g + 1 < kGroupsPerRun) {
          unpack_block_neon<false>(row, g, dst, k);
        } else {
          unpack_block_neon<true>(row, g, dst, k);
        }
      });
    }
  }
}

}  // namespace tofmat::kinect

#endif  // __aarch64__
