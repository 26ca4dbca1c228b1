// The Kinect v2's 11-bit sample code and its 16-bit value: bit 10 is the
// sign, the low 10 bits a companded magnitude (steps of 1 up to 256, then 2,
// 4, ..., 64 per 128-code block, reaching 16320); code 1024 ("minus zero") is
// the saturation marker 32767. Facts: shared/docs/kinect2-protocol.md 2.4.
#pragma once

#include <cstdint>

namespace tofmat {

inline constexpr std::int16_t kRawSaturated = 32767;
inline constexpr std::int32_t kRawMaxMagnitude = 16320;
inline constexpr std::uint16_t kRawSaturationCode = 1024;

// Value of an 11-bit code (only the low 11 bits are used).
std::int16_t raw_code_value(std::uint16_t code);

// The code whose value is nearest to v; |v| > 16320 clamps to +-16320 (the
// saturation marker is set by the caller, who knows whether the pixel saturated).
std::uint16_t raw_code_nearest(double v);

}  // namespace tofmat
