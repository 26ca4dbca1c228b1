// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The float reference decode of a raw frame or a pixel region into per-frequency phase, amplitude and depth, and flags.
#include "tofmat/core/frame_decode.hpp"

#include <cmath>
#include <complex>
#include <stdexcept>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/features.hpp"
#include "tofmat/core/raw_lut.hpp"

namespace tofmat {

namespace {

DecodedFrame allocate(std::size_t pixels) {
  DecodedFrame out;
  out.pixels = pixels;
  for (std::size_t g = 0; g < 3; ++g) {
    out.phase_rad[g].assign(pixels, 0.0f);
    out.amplitude[g].assign(pixels, 0.0f);
    out.depth_mm[g].assign(pixels, NAN);
  }
  out.combined_mm.assign(pixels, NAN);
  for (auto& f : out.features) f.assign(pixels, NAN);
  out.flags.assign(pixels, 0);
  return out;
}

// e^{-i phi_j} of the three phase steps.
const std::array<std::complex<double>, 3> kStepRotations = {
    std::polar(1.0, -kPhaseStepsRad[0]), std::polar(1.0, -kPhaseStepsRad[1]), std::polar(1.0, -kPhaseStepsRad[2])};

// Pixel `src` of a frame of `stride` pixels, with the corrections of entry
// `ti` of `t`, into slot `dst` of `out`:
// a + i b = e^{-i p0} sum_j m_j e^{-i phi_j} (phasor_from_samples, factored).
void decode_pixel(const std::int16_t* raw, std::size_t stride, std::size_t src, const DecodeTables& t, std::size_t ti,
                  const DecodeOptions& options, DecodedFrame& out, std::size_t dst) {
  std::array<double, 3> wrapped{};
  std::array<double, 3> amp{};
  std::uint8_t flags = 0;
  for (std::size_t g = 0; g < 3; ++g) {
    std::complex<double> sum{0.0, 0.0};
    for (std::size_t j = 0; j < 3; ++j) {
      const std::int16_t v = raw[(g * 3 + j) * stride + src];
      if (v == kRawSaturated) flags |= kDecodeSaturated;
      sum += static_cast<double>(v) * kStepRotations[j];
    }
    const std::complex<double> rot{t.cos_p0[g][ti], -static_cast<double>(t.sin_p0[g][ti])};
    const auto z = sum * rot;
    amp[g] = std::sqrt(std::norm(z)) / 1.5;  // (no overflow from int16 sums: no hypot needed)
    const double phase = phase_of(z);
    out.phase_rad[g][dst] = static_cast<float>(phase);
    out.amplitude[g][dst] = static_cast<float>(amp[g]);
    if (!(amp[g] >= options.min_amplitude)) flags |= kDecodeDark;
    wrapped[g] = depth_from_phase_mm(phase, kGroupFrequenciesMhz[g]);
  }
  // The mean against the combined threshold (as the sum against 3 x it: no division).
  if (!(amp[0] + amp[1] + amp[2] >= 3.0 * options.min_mean_amplitude)) flags |= kDecodeDark;
  if (flags) {
    out.flags[dst] = flags;
    return;
  }
  const UnwrappedDepth u = unwrap_depths(wrapped);
  if (!(amp[kGroup16] >= options.min_unwrap_amplitude) ||
      !unwrap_consistent(u, options.max_gap_16_80_mm, options.max_gap_80_120_mm)) {
    out.flags[dst] = kDecodeUnwrap;
    return;
  }
  out.flags[dst] = 0;
  for (std::size_t g = 0; g < 3; ++g) out.depth_mm[g][dst] = static_cast<float>(wrapped[g]);
  out.combined_mm[dst] = static_cast<float>(u.combined_mm);
  out.features[0][dst] = static_cast<float>(wrapped[kGroup16] - wrapped[kGroup120]);
  out.features[1][dst] = static_cast<float>(wrapped[kGroup80] - wrapped[kGroup120]);
}

void check_region(int width, int height, const PixelRegion& r) {
  if (width < 1 || height < 1) throw std::invalid_argument("frame size must be positive");
  if (r.x0 < 0 || r.y0 < 0 || r.x1 > width || r.y1 > height || r.x0 >= r.x1 || r.y0 >= r.y1) {
    throw std::invalid_argument("decode region is empty or outside the frame");
  }
}

// The region's pixels of a frame of width x height, row by row: `table_index`
// maps a region slot to the entry of the tables (its frame index for the
// frame's tables, the slot itself for the region's).
template <typename TableIndex>
DecodedFrame decode_region_pixels(const std::int16_t* raw, int width, int height, const DecodeTables& t,
                                  const PixelRegion& r, const DecodeOptions& options, TableIndex table_index) {
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  const std::size_t rw = static_cast<std::size_t>(r.x1 - r.x0);
  DecodedFrame out = allocate(rw * static_cast<std::size_t>(r.y1 - r.y0));
  std::size_t k = 0;
  for (int y = r.y0; y < r.y1; ++y) {
    const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(width);
    for (int x = r.x0; x < r.x1; ++x, ++k) {
      const std::size_t src = row + static_cast<std::size_t>(x);
      decode_pixel(raw, pixels, src, t, table_index(src, k), options, out, k);
    }
  }
  return out;
}

}  // namespace

DecodeTables::DecodeTables(const std::vector<float>& p0_rad, std::size_t n) : pixels(n) {
  if (!p0_rad.empty() && p0_rad.size() != 3 * n)
    throw std::invalid_argument("p0 corrections must hold 3 x pixels values");
  for (std::size_t g = 0; g < 3; ++g) {
    cos_p0[g].assign(n, 1.0f);
    sin_p0[g].assign(n, 0.0f);
    if (p0_rad.empty()) continue;
    for (std::size_t i = 0; i < n; ++i) {
      const double p = p0_rad[g * n + i];
      cos_p0[g][i] = static_cast<float>(std::cos(p));
      sin_p0[g][i] = static_cast<float>(std::sin(p));
    }
  }
}

DecodedFrame decode_frame(const std::int16_t* raw, std::size_t pixels, const std::vector<float>& p0_rad,
                          const DecodeOptions& options) {
  return decode_frame(raw, DecodeTables(p0_rad, pixels), options);
}

DecodedFrame decode_frame(const std::int16_t* raw, const DecodeTables& t, const DecodeOptions& options) {
  DecodedFrame out = allocate(t.pixels);
  for (std::size_t i = 0; i < t.pixels; ++i) decode_pixel(raw, t.pixels, i, t, i, options, out, i);
  return out;
}

DecodedFrame decode_region(const std::int16_t* raw, int width, int height, const std::vector<float>& p0_rad,
                           const PixelRegion& r, const DecodeOptions& options) {
  check_region(width, height, r);
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (!p0_rad.empty() && p0_rad.size() != 3 * pixels)
    throw std::invalid_argument("p0 corrections must hold 3 x pixels values");
  // Tables of the region's pixels only (slot order), from the same float
  // corrections: the same cos/sin values as the whole frame's tables.
  const std::size_t rw = static_cast<std::size_t>(r.x1 - r.x0);
  const std::size_t n = rw * static_cast<std::size_t>(r.y1 - r.y0);
  std::vector<float> p0_region;
  if (!p0_rad.empty()) {
    p0_region.resize(3 * n);
    for (std::size_t g = 0; g < 3; ++g) {
      std::size_t k = 0;
      for (int y = r.y0; y < r.y1; ++y) {
        const std::size_t row = g * pixels + static_cast<std::size_t>(y) * static_cast<std::size_t>(width);
        for (int x = r.x0; x < r.x1; ++x) p0_region[g * n + k++] = p0_rad[row + static_cast<std::size_t>(x)];
      }
    }
  }
  const DecodeTables t(p0_region, n);
  return decode_region_pixels(raw, width, height, t, r, options, [](std::size_t, std::size_t k) { return k; });
}

DecodedFrame decode_region(const std::int16_t* raw, int width, int height, const DecodeTables& t, const PixelRegion& r,
                           const DecodeOptions& options) {
  check_region(width, height, r);
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (t.pixels != pixels) throw std::invalid_argument("decode tables are for a frame of another size");
  return decode_region_pixels(raw, width, height, t, r, options, [](std::size_t src, std::size_t) { return src; });
}

}  // namespace tofmat
