// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The Kinect v2 command protocol (kinect2-protocol.md 1.4-1.7): command
// encoding, the completion record, and parsers for the responses the driver
// uses. Every parser bounds its reads by the response's length and throws
// tofmat::FormatError naming what was wrong.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace tofmat::kinect {

inline constexpr std::uint32_t kCommandMagic = 0x06022009;
inline constexpr std::uint32_t kCompletionMagic = 0x0A6FE000;
inline constexpr std::size_t kCompletionBytes = 16;
inline constexpr std::size_t kMaxCommandParams = 4;
// The largest response stage of any command (ReadDataPage of the tables, 1.6):
// a late response of a timed-out command can be this long.
inline constexpr std::uint32_t kMaxResponseBytes = 0x1C0000;

// Command IDs (1.6).
enum class CommandId : std::uint32_t {
  kShutdown = 0x00,
  kReadFirmwareVersions = 0x02,
  kInitStreams = 0x09,
  kStop = 0x0A,
  kReadHardwareInfo = 0x14,
  kReadStatus = 0x16,
  kReadDataPage = 0x22,
  kSetStreaming = 0x2B,
  kSetMode = 0x4B,
};

// Data pages of ReadDataPage.
inline constexpr std::uint32_t kPageSerial = 0x01;
inline constexpr std::uint32_t kPageP0Tables = 0x02;
inline constexpr std::uint32_t kPageDepthParams = 0x03;
inline constexpr std::uint32_t kPageColorParams = 0x04;
inline constexpr std::uint32_t kStatusRequest = 0x090000;

struct Command {
  CommandId id;
  std::uint32_t max_response = 0;  // bytes; 0 = no response stage
  std::vector<std::uint32_t> params;
};

// Named commands with their response limits (1.6).
Command cmd_read_firmware_versions();
Command cmd_read_hardware_info();
Command cmd_read_data_page(std::uint32_t page);
Command cmd_read_status();
Command cmd_set_mode(bool on, std::uint32_t value = 0);
Command cmd_init_streams();
Command cmd_set_streaming(bool on);
Command cmd_stop();
Command cmd_shutdown();

// The bytes sent on the command endpoint: magic, sequence, max response,
// id, reserved, then 0, 1 or 4 parameters (20, 24 or 36 bytes). Throws
// std::invalid_argument for 2, 3 or more than 4 parameters.
std::vector<std::uint8_t> encode_command(const Command& c, std::uint32_t sequence);

// The device side's view of a command (the simulated device parses what the
// driver sends). Throws FormatError on a wrong size or magic.
struct DecodedCommand {
  std::uint32_t sequence = 0;
  std::uint32_t max_response = 0;
  std::uint32_t id = 0;
  std::vector<std::uint32_t> params;
};
DecodedCommand decode_command(const std::uint8_t* data, std::size_t size);

// The 16-byte completion that ends every transaction: magic and the echoed
// sequence. Throws FormatError if the size or the magic is wrong.
struct Completion {
  std::uint32_t sequence = 0;
  std::uint32_t word2 = 0, word3 = 0;
};
Completion parse_completion(const std::uint8_t* data, std::size_t size);
std::vector<std::uint8_t> encode_completion(std::uint32_t sequence);
// True when a response buffer is really a completion (premature completion).
bool looks_like_completion(const std::uint8_t* data, std::size_t size);

// --- responses -----------------------------------------------------------

struct FirmwareVersion {
  std::uint16_t major = 0, minor = 0;
  std::uint32_t revision = 0, build = 0;
  std::string to_string() const;
};
// Up to 7 16-byte records {maj_min, revision, build, reserved}; at least one.
std::vector<FirmwareVersion> parse_firmware_versions(const std::uint8_t* data, std::size_t size);

// Serial number: the even-indexed bytes (UTF-16LE ASCII) up to a NUL; must be
// printable ASCII and non-empty.
std::string parse_serial(const std::uint8_t* data, std::size_t size);

// Depth camera intrinsics (23 floats, the first 10 named).
struct DepthParams {
  float fx = 0, fy = 0, cx = 0, cy = 0, k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
};
inline constexpr std::size_t kDepthParamsBytes = 23 * 4;
DepthParams parse_depth_params(const std::uint8_t* data, std::size_t size);
// Throws FormatError unless every value is finite, the focal lengths are
// positive, the principal point lies inside the 512 x 424 image and the
// distortion coefficients are at most 10 in size (the Kinect's are under 1):
// parse_depth_params's check, and a recording's.
void check_depth_params(const DepthParams& p);
std::vector<std::uint8_t> encode_depth_params(const DepthParams& p);

// P0 tables (3.1): 32-byte header, then three blocks of (pad, 512 x 424
// uint16, pad) in output orientation. The per-pixel phase correction is
// p0 = -P0 * 0.000031 * pi radians (table k serves group k).
inline constexpr std::size_t kP0HeaderBytes = 32;
inline constexpr std::size_t kP0BlockBytes = 2 + 512 * 424 * 2 + 2;                // 434,180
inline constexpr std::size_t kP0TablesBytes = kP0HeaderBytes + 3 * kP0BlockBytes;  // 1,302,572
inline constexpr double kP0RadPerUnit = 0.000031 * 3.14159265358979323846;
struct P0Tables {
  std::array<std::vector<std::uint16_t>, 3> raw;  // 512 x 424 each, output orientation
  // -raw * kP0RadPerUnit per pixel, 3 x 512 x 424 group-major: what decode_frame takes.
  std::vector<float> p0_rad() const;
};
P0Tables parse_p0_tables(const std::uint8_t* data, std::size_t size);
std::vector<std::uint8_t> encode_p0_tables(const P0Tables& t);
// The table value that makes the decode's p0 equal p0_rad (wrapped into the
// table's range [0, 2 pi)).
std::uint16_t p0_table_value(double p0_rad);

// ReadStatus: one uint32; bit 0 set = ready to stream.
std::uint32_t parse_status(const std::uint8_t* data, std::size_t size);

}  // namespace tofmat::kinect
