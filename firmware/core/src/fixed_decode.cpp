// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The fixed-point decode of frames and regions: the scalar CORDIC kernel, unwrapping, flags and kernel dispatch.
#include "tofmat/core/fixed_decode.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/raw_lut.hpp"

namespace tofmat {

namespace fixed_decode_detail {
// round(2^25 * 256 / (3 K)), K = prod sqrt(1 + 2^-2i), i = 0..5, = 1.6464922787...
const std::uint32_t kAmpScale = 1739037327u;
}  // namespace fixed_decode_detail

namespace {

using namespace fixed_decode_detail;

// Unambiguous ranges c / (2 f) with the device's c = 300 mm/ns, in Q16 mm.
constexpr std::int32_t kRangeMm[3] = {1875, 9375, 1250};
constexpr std::int32_t kRangeQ16[3] = {1875 << 16, 9375 << 16, 1250 << 16};
// ceil(2^32 / 27): floor(n / 27) as (n * M) >> 32, exact for 0 <= n < 8.6e8.
constexpr std::int64_t kInv27 = 159072863;

int leading_zeros(std::uint32_t v) { return __builtin_clz(v | 1u); }

}  // namespace

void phase_amplitude_scalar(const std::int16_t* m0, const std::int16_t* m1, const std::int16_t* m2,
                            const std::uint32_t* p0, std::size_t n, std::uint32_t* phase, std::uint32_t* amp_q8,
                            std::uint8_t* flags) {
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t a0 = m0[i], a1 = m1[i], a2 = m2[i];
    if (a0 == kRawSaturated || a1 == kRawSaturated || a2 == kRawSaturated) flags[i] |= kDecodeSaturated;
    // 2 (a + i b) = (2 m0 - m1 - m2) + i sqrt(3) (m2 - m1): the phasor of the
    // three steps, times 2 (exact in int32: |X| <= 131068, |W| <= 65534).
    const std::int32_t X = 2 * a0 - a1 - a2, W = a2 - a1;
    if (X == 0 && W == 0) {  // no signal: phase 0 (as phase_of), amplitude 0
      phase[i] = 0;
      amp_q8[i] = 0;
      continue;
    }
    // Scale so that max(|X|, |W|) < 2^28: the CORDIC then works at full
    // precision whatever the signal, and K |v| < 2^30 cannot overflow.
    const auto mx = static_cast<std::uint32_t>(std::max(X < 0 ? -X : X, W < 0 ? -W : W));
    const int sh = std::max(0, leading_zeros(mx) - 4);
    std::int32_t x = X * (1 << sh);
    std::int32_t y = 2 * rounding_doubling_mul_high(W * (1 << sh), kHalfSqrt3Q31);
    std::uint32_t angle = 0;
    if (x < 0) {  // into the right half-plane: a half turn
      x = -x;
      y = -y;
      angle = 0x80000000u;
    }
    // y >= 0: x += y >> k, y -= x >> k, angle += atan(2^-k); else the
    // opposite. Branch-free (the direction is a coin flip per step): m is -1
    // for "else", and (v ^ m) - m is v or -v. (y = 0 could turn either way;
    // ">= 0" is what AVX2's sign instruction does with y | 1 in one step.)
    for (int k = 0; k < kCordicSteps; ++k) {
      const std::int32_t xs = x >> k, ys = y >> k;  // arithmetic shifts (as NEON's)
      const std::int32_t m = -static_cast<std::int32_t>(y < 0);
      x += (ys ^ m) - m;
      y -= (xs ^ m) - m;
      const auto um = static_cast<std::uint32_t>(m);
      angle += (kAtanTurns[static_cast<std::size_t>(k)] ^ um) - um;
    }
    // The residual angle, |t| = |y / x| <= tan(atan(2^-5)) (x > 0 after the
    // first step): one correctly rounded division, then atan t = t - t^3 / 3
    // and the magnitude x (1 + t^2 / 2) in binary32, each product rounded
    // once, conversions rounding to nearest even as _mm256_cvtps_epi32 and
    // vcvtnq_s32_f32 do.
    const float xf = static_cast<float>(x);
    const float t = static_cast<float>(y) / xf;
    const float t2 = t * t;
    const float r = t - (t * t2) * kThirdF;
    angle += static_cast<std::uint32_t>(static_cast<std::int32_t>(std::nearbyint(r * kTurnsPerRadF)));
    x += static_cast<std::int32_t>(std::nearbyint((xf * t2) * 0.5f));  // < 2^30 (1 + 4.9e-4)
    phase[i] = angle - p0[i];                                          // mod 2^32: the wrap into [0, 2 pi)
    amp_q8[i] = static_cast<std::uint32_t>((static_cast<std::uint64_t>(static_cast<std::uint32_t>(x)) * kAmpScale) >>
                                           (kAmpScaleBits + sh));
  }
}

FixedDecodeTables::FixedDecodeTables(const std::vector<float>& p0_rad, std::size_t n) : pixels(n) {
  if (!p0_rad.empty() && p0_rad.size() != 3 * n)
    throw std::invalid_argument("p0 corrections must hold 3 x pixels values");
  const double turns_per_rad = 4294967296.0 / (2.0 * kPi);
  for (std::size_t g = 0; g < 3; ++g) {
    auto& t = p0_turns[g];
    t.assign(n, 0u);
    if (p0_rad.empty()) continue;
    for (std::size_t i = 0; i < n; ++i) {
      const double r = std::remainder(static_cast<double>(p0_rad[g * n + i]), 2.0 * kPi);  // |r| <= pi
      t[i] = static_cast<std::uint32_t>(static_cast<std::int64_t>(std::llround(r * turns_per_rad)));
    }
  }
}

namespace {

std::uint32_t q8_counts(double v) {
  if (!(v > 0.0)) return 0;
  return static_cast<std::uint32_t>(std::min(std::ceil(v * 256.0), 4294967295.0));
}
std::int64_t q16_mm(double v) {
  if (!(v >= 0.0)) return -1;  // NaN or negative: nothing passes
  return static_cast<std::int64_t>(std::min(std::floor(v * 65536.0), 9.0e18));
}

}  // namespace

FixedThresholds fixed_thresholds(const DecodeOptions& o) {
  return {q8_counts(o.min_amplitude), q8_counts(3.0 * o.min_mean_amplitude), q8_counts(o.min_unwrap_amplitude),
          q16_mm(o.max_gap_16_80_mm), q16_mm(o.max_gap_80_120_mm)};
}

void finish_pixels_scalar(const FixedPlanes& p, std::size_t n, const FixedThresholds& th) {
  for (std::size_t k = 0; k < n; ++k) {
    for (std::size_t g = 0; g < 3; ++g) p.depth[g][k] = kFixedInvalid;
    p.combined[k] = p.features[0][k] = p.features[1][k] = kFixedInvalid;
    std::int32_t d[3];
    std::uint64_t amp_sum = 0;
    bool dark = false;
    for (std::size_t g = 0; g < 3; ++g) {
      d[g] = static_cast<std::int32_t>(
          (static_cast<std::uint64_t>(p.phase[g][k]) * static_cast<std::uint64_t>(kRangeMm[g])) >> 16);
      dark = dark || p.amp[g][k] < th.amp;
      amp_sum += p.amp[g][k];
    }
    if (dark || amp_sum < th.mean_sum) p.flags[k] |= kDecodeDark;
    if (p.flags[k]) continue;
    // Hierarchical unwrap as unwrap_depths: D80 = d80 + k R80 nearest to D16,
    // D120 = d120 + k' R120 nearest to D80 (halves round up), offsets keep the
    // dividends positive.
    const std::int32_t D16 = d[kGroup16];
    const std::int32_t k80 =
        (D16 - d[kGroup80] + kRangeQ16[kGroup80] / 2 + kRangeQ16[kGroup80]) / kRangeQ16[kGroup80] - 1;
    const std::int32_t D80 = d[kGroup80] + k80 * kRangeQ16[kGroup80];
    const std::int32_t k120 =
        (D80 - d[kGroup120] + kRangeQ16[kGroup120] / 2 + 2 * kRangeQ16[kGroup120]) / kRangeQ16[kGroup120] - 2;
    const std::int32_t D120 = d[kGroup120] + k120 * kRangeQ16[kGroup120];
    const std::int64_t gap1 = std::abs(static_cast<std::int64_t>(D80) - D16);
    const std::int64_t gap2 = std::abs(static_cast<std::int64_t>(D120) - D80);
    if (p.amp[kGroup16][k] < th.unwrap_amp || gap1 > th.gap_16_80 || gap2 > th.gap_80_120) {
      p.flags[k] = kDecodeUnwrap;
      continue;
    }
    for (std::size_t g = 0; g < 3; ++g) p.depth[g][k] = d[g];
    // (80 D80 + 16 D16 + 120 D120) / 216 = (10 D80 + 2 D16 + 15 D120) / 27, in Q8.
    const std::int64_t num8 = (10 * static_cast<std::int64_t>(D80) + 2 * static_cast<std::int64_t>(D16) +
                               15 * static_cast<std::int64_t>(D120)) >>
                              (kDepthFracBits - kCombinedFracBits);
    p.combined[k] = static_cast<std::int32_t>((num8 * kInv27) >> 32);
    p.features[0][k] = d[kGroup16] - d[kGroup120];
    p.features[1][k] = d[kGroup80] - d[kGroup120];
  }
}

namespace {

void finish_pixels(FixedKernel kernel, const FixedPlanes& p, std::size_t n, const FixedThresholds& th) {
#if defined(__x86_64__)
  if (kernel == FixedKernel::kBest && cpu_has_avx2()) return finish_pixels_avx2(p, n, th);
#elif defined(__aarch64__)
  if (kernel == FixedKernel::kBest) return finish_pixels_neon(p, n, th);
#endif
  (void)kernel;
  finish_pixels_scalar(p, n, th);
}

void phase_amplitude(FixedKernel kernel, const std::int16_t* m0, const std::int16_t* m1, const std::int16_t* m2,
                     const std::uint32_t* p0, std::size_t n, std::uint32_t* phase, std::uint32_t* amp,
                     std::uint8_t* flags) {
#if defined(__aarch64__)
  if (kernel == FixedKernel::kBest) return phase_amplitude_neon(m0, m1, m2, p0, n, phase, amp, flags);
#elif defined(__x86_64__)
  if (kernel == FixedKernel::kBest && cpu_has_avx2()) return phase_amplitude_avx2(m0, m1, m2, p0, n, phase, amp, flags);
#endif
  (void)kernel;
  phase_amplitude_scalar(m0, m1, m2, p0, n, phase, amp, flags);
}

}  // namespace

// (Every plane other than the flags is written whole by the kernels and the
// finishing stage; decode_pixels_fixed clears the flags it ORs into.)
void size_fixed_frame(FixedDecodedFrame& out, std::size_t pixels) {
  out.pixels = pixels;
  for (std::size_t g = 0; g < 3; ++g) {
    out.phase_turns[g].resize(pixels);
    out.amplitude_q8[g].resize(pixels);
    out.depth_q16[g].resize(pixels);
  }
  out.combined_q8.resize(pixels);
  for (auto& f : out.features_q16) f.resize(pixels);
  out.flags.resize(pixels);
}

FixedPlanes planes_from(const FixedPlanes& p, std::size_t at) {
  FixedPlanes rest = p;
  for (std::size_t g = 0; g < 3; ++g) {
    rest.phase[g] += at;
    rest.amp[g] += at;
    rest.depth[g] += at;
  }
  rest.flags += at;
  rest.combined += at;
  rest.features[0] += at;
  rest.features[1] += at;
  return rest;
}

FixedPlanes planes_of(FixedDecodedFrame& f, std::size_t at) {
  if (at > f.pixels || f.flags.size() != f.pixels) throw std::invalid_argument("planes beyond the frame");
  FixedPlanes p;
  for (std::size_t g = 0; g < 3; ++g) {
    p.phase[g] = f.phase_turns[g].data() + at;
    p.amp[g] = f.amplitude_q8[g].data() + at;
    p.depth[g] = f.depth_q16[g].data() + at;
  }
  p.flags = f.flags.data() + at;
  p.combined = f.combined_q8.data() + at;
  p.features[0] = f.features_q16[0].data() + at;
  p.features[1] = f.features_q16[1].data() + at;
  return p;
}

void decode_pixels_fixed(const std::int16_t* raw, const FixedDecodeTables& t, std::size_t first, std::size_t n,
                         const FixedThresholds& th, const FixedPlanes& out, FixedKernel kernel) {
  if (first > t.pixels || n > t.pixels - first) throw std::invalid_argument("pixels beyond the frame");
  const std::size_t N = t.pixels;
  std::fill(out.flags, out.flags + n, std::uint8_t{0});
  for (std::size_t g = 0; g < 3; ++g) {
    const std::int16_t* m = raw + 3 * g * N + first;
    phase_amplitude(kernel, m, m + N, m + 2 * N, t.p0_turns[g].data() + first, n, out.phase[g], out.amp[g], out.flags);
  }
  finish_pixels(kernel, out, n, th);
}

void decode_frame_fixed(const std::int16_t* raw, const FixedDecodeTables& t, FixedDecodedFrame& out,
                        const DecodeOptions& options, FixedKernel kernel) {
  size_fixed_frame(out, t.pixels);
  decode_pixels_fixed(raw, t, 0, t.pixels, fixed_thresholds(options), planes_of(out, 0), kernel);
}

FixedDecodedFrame decode_frame_fixed(const std::int16_t* raw, const FixedDecodeTables& t, const DecodeOptions& options,
                                     FixedKernel kernel) {
  FixedDecodedFrame out;
  decode_frame_fixed(raw, t, out, options, kernel);
  return out;
}

FixedDecodedFrame decode_region_fixed(const std::int16_t* raw, int width, int height, const FixedDecodeTables& t,
                                      const PixelRegion& r, const DecodeOptions& options, FixedKernel kernel) {
  FixedDecodedFrame out;
  decode_region_fixed(raw, width, height, t, r, out, options, kernel);
  return out;
}

void decode_region_fixed(const std::int16_t* raw, int width, int height, const FixedDecodeTables& t,
                         const PixelRegion& r, FixedDecodedFrame& out, const DecodeOptions& options,
                         FixedKernel kernel) {
  if (width < 1 || height < 1) throw std::invalid_argument("frame size must be positive");
  if (r.x0 < 0 || r.y0 < 0 || r.x1 > width || r.y1 > height || r.x0 >= r.x1 || r.y0 >= r.y1) {
    throw std::invalid_argument("decode region is empty or outside the frame");
  }
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (t.pixels != n) throw std::invalid_argument("decode tables are for a frame of another size");
  const std::size_t rw = static_cast<std::size_t>(r.x1 - r.x0);
  size_fixed_frame(out, rw * static_cast<std::size_t>(r.y1 - r.y0));
  std::fill(out.flags.begin(), out.flags.end(), std::uint8_t{0});  // (the kernels OR saturation into them)
  for (int y = r.y0; y < r.y1; ++y) {                              // a row of the region is contiguous in every plane
    const std::size_t src =
        static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + static_cast<std::size_t>(r.x0);
    const std::size_t dst = static_cast<std::size_t>(y - r.y0) * rw;
    for (std::size_t g = 0; g < 3; ++g) {
      const std::int16_t* m = raw + 3 * g * n + src;
      phase_amplitude(kernel, m, m + n, m + 2 * n, t.p0_turns[g].data() + src, rw, out.phase_turns[g].data() + dst,
                      out.amplitude_q8[g].data() + dst, out.flags.data() + dst);
    }
  }
  finish_pixels(kernel, planes_of(out, 0), out.pixels, fixed_thresholds(options));
}

}  // namespace tofmat
