// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Fixed facts of the Kinect v2 (Xbox One Kinect) USB device and its depth
// stream, from shared/docs/kinect2-protocol.md (sections cited per group).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

namespace tofmat::kinect {

// 1.1: identities.
inline constexpr std::uint16_t kVendorId = 0x045E;
inline constexpr std::uint16_t kProductId = 0x02D8;         // release Kinect v2 / Xbox One Kinect
inline constexpr std::uint16_t kProductIdPreview = 0x02C4;  // developer preview

// 1.2: configuration, interfaces, endpoints.
inline constexpr int kConfiguration = 1;
inline constexpr int kControlInterface = 0;
inline constexpr int kDepthInterface = 1;
inline constexpr int kDepthAltOff = 0;
inline constexpr int kDepthAltStreaming = 1;
inline constexpr std::uint8_t kCommandOutEndpoint = 0x02;
inline constexpr std::uint8_t kResponseInEndpoint = 0x81;
inline constexpr std::uint8_t kDepthIsoEndpoint = 0x84;
inline constexpr std::size_t kMinIsoPacketBytes = 0x8400;  // below this the device cannot stream depth
inline constexpr int kIsoTransfers = 60;                   // transfers kept in flight
inline constexpr int kIsoPacketsPerTransfer = 8;
inline constexpr unsigned kTimeoutMs = 1000;  // control, commands, stream transfers

// 2.1-2.3: the depth stream.
inline constexpr int kWidth = 512;
inline constexpr int kHeight = 424;
inline constexpr std::size_t kPixels = static_cast<std::size_t>(kWidth) * kHeight;
inline constexpr std::size_t kRowBytes = 704;                                  // 512 x 11 bits, 352 LE words
inline constexpr std::size_t kSubImageBytes = kRowBytes * kHeight;             // 298,496
inline constexpr std::size_t kFooterBytes = 152;                               // 6 + 32 uint32
inline constexpr std::size_t kSubPacketBytes = kSubImageBytes + kFooterBytes;  // 298,648
inline constexpr int kSubImages = 10;                                          // per depth packet (9 used)
inline constexpr int kUsedSubImages = 9;                                       // 3 groups x 3 phase steps
inline constexpr std::size_t kDepthPacketBytes = kSubImageBytes * kSubImages;  // 2,984,960
inline constexpr std::uint32_t kAllSubImages = (1u << kSubImages) - 1;         // 0x3FF

}  // namespace tofmat::kinect
