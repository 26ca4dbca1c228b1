#include "tofmat/core/frame_decode.hpp"

#include <cmath>
#include <stdexcept>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/features.hpp"
#include "tofmat/core/raw_lut.hpp"

namespace tofmat {

DecodedFrame decode_frame(const std::int16_t* raw, std::size_t pixels, const std::vector<float>& p0_rad,
                          const DecodeOptions& options) {
  if (!p0_rad.empty() && p0_rad.size() != 3 * pixels) {
    throw std::invalid_argument("p0 corrections must hold 3 x pixels values");
  }
  DecodedFrame out;
  out.pixels = pixels;
  for (std::size_t g = 0; g < 3; ++g) {
    out.phase_rad[g].assign(pixels, 0.0f);
    out.amplitude[g].assign(pixels, 0.0f);
    out.depth_mm[g].assign(pixels, NAN);
  }
  out.combined_mm.assign(pixels, NAN);
  out.flags.assign(pixels, 0);
  for (std::size_t i = 0; i < pixels; ++i) {
    std::array<double, 3> wrapped{};
    std::uint8_t flags = 0;
    for (std::size_t g = 0; g < 3; ++g) {
      double m[3];
      for (std::size_t j = 0; j < 3; ++j) {
        const std::int16_t v = raw[(g * 3 + j) * pixels + i];
        if (v == kRawSaturated) flags |= kDecodeSaturated;
        m[j] = v;
      }
      const double p0 = p0_rad.empty() ? 0.0 : p0_rad[g * pixels + i];
      const auto z = phasor_from_samples(m, p0);
      const double amp = std::abs(z) / 1.5;
      const double phase = phase_of(z);
      out.phase_rad[g][i] = static_cast<float>(phase);
      out.amplitude[g][i] = static_cast<float>(amp);
      if (!(amp >= options.min_amplitude)) flags |= kDecodeDark;
      wrapped[g] = depth_from_phase_mm(phase, kGroupFrequenciesMhz[g]);
    }
    out.flags[i] = flags;
    if (flags) continue;
    for (std::size_t g = 0; g < 3; ++g) out.depth_mm[g][i] = static_cast<float>(wrapped[g]);
    out.combined_mm[i] = static_cast<float>(unwrap_depths(wrapped).combined_mm);
  }
  return out;
}

}  // namespace tofmat
