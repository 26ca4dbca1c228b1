// The depth sub-image's packed 11-bit layout (kinect2-protocol.md 2.3) and its
// inverse. Rows: stored rows 0..211 are output rows 0..211, stored rows
// 212..423 are output rows 423 down to 212. Columns: output column x is slot
// 128 (x mod 4) + floor(x / 4) of its stored row, an 11-bit code at bit 11 p
// of the row read LSB-first from little-endian 16-bit words. Columns 0 and
// 511 always read code 0. Output orientation is the image orientation of the
// whole project (row 0 at the top), the one the P0 tables use.
#pragma once

#include <cstddef>
#include <cstdint>

namespace tofmat::kinect {

// The stored row that carries output row y.
int stored_row_of_output_row(int y);

// 11-bit codes of one sub-image (kSubImageBytes) in output orientation:
// codes[y * 512 + x]. Reads exactly kSubImageBytes.
void unpack_codes(const std::uint8_t* sub_image, std::uint16_t* codes);

// The same, mapped through the device's lookup table to 16-bit raw values
// (32767 = saturated): what the decode takes.
void unpack_raw(const std::uint8_t* sub_image, std::int16_t* raw);

// All nine used sub-images of a depth packet (kDepthPacketBytes, or at least
// 9 x kSubImageBytes) into raw[9 * kPixels], sub-image-major.
void unpack_depth_packet(const std::uint8_t* packet, std::int16_t* raw);

// The device side: pack output-orientation codes (low 11 bits used) into a
// sub-image (kSubImageBytes, fully written). Columns 0 and 511 are packed as
// given; the reader ignores them.
void pack_codes(const std::uint16_t* codes, std::uint8_t* sub_image);

}  // namespace tofmat::kinect
