// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The Kinect v2 command codec: command and completion records, and the parsers of the responses the driver uses.
#include "tofmat/kinect/command.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "tofmat/core/byte_reader.hpp"
#include "tofmat/core/byte_writer.hpp"
#include "tofmat/core/error.hpp"

namespace tofmat::kinect {
namespace {

constexpr std::uint32_t kPageMaxResponse = kMaxResponseBytes;

float f32(ByteReader& r, const char* field) {
  const std::uint32_t bits = r.u32(field);
  float v;
  std::memcpy(&v, &bits, sizeof v);
  return v;
}

}  // namespace

Command cmd_read_firmware_versions() { return {CommandId::kReadFirmwareVersions, 0x200, {}}; }
Command cmd_read_hardware_info() { return {CommandId::kReadHardwareInfo, 0x5C, {}}; }
Command cmd_read_data_page(std::uint32_t page) {
  return {CommandId::kReadDataPage, page == kPageSerial ? 0x80u : kPageMaxResponse, {page}};
}
Command cmd_read_status() { return {CommandId::kReadStatus, 4, {kStatusRequest}}; }
Command cmd_set_mode(bool on, std::uint32_t value) { return {CommandId::kSetMode, 0, {on ? 1u : 0u, value, 0, 0}}; }
Command cmd_init_streams() { return {CommandId::kInitStreams, 0, {}}; }
Command cmd_set_streaming(bool on) { return {CommandId::kSetStreaming, 0, {on ? 1u : 0u}}; }
Command cmd_stop() { return {CommandId::kStop, 0, {}}; }
Command cmd_shutdown() { return {CommandId::kShutdown, 0, {}}; }

std::vector<std::uint8_t> encode_command(const Command& c, std::uint32_t sequence) {
  const std::size_t n = c.params.size();
  if (n != 0 && n != 1 && n != kMaxCommandParams) throw std::invalid_argument("a command has 0, 1 or 4 parameters");
  ByteWriter w;
  w.u32(kCommandMagic);
  w.u32(sequence);
  w.u32(c.max_response);
  w.u32(static_cast<std::uint32_t>(c.id));
  w.u32(0);
  for (std::uint32_t p : c.params) w.u32(p);
  return w.take();
}

DecodedCommand decode_command(const std::uint8_t* data, std::size_t size) {
  if (size != 20 && size != 24 && size != 36) {
    throw FormatError("command: " + std::to_string(size) + " bytes (a command is 20, 24 or 36)");
  }
  ByteReader r(data, size, "command");
  if (r.u32("magic") != kCommandMagic) throw FormatError("command: wrong magic");
  DecodedCommand d;
  d.sequence = r.u32("sequence");
  d.max_response = r.u32("max_response_length");
  d.id = r.u32("command_id");
  r.u32("reserved");
  while (r.remaining() > 0) d.params.push_back(r.u32("parameter"));
  return d;
}

Completion parse_completion(const std::uint8_t* data, std::size_t size) {
  if (size != kCompletionBytes) {
    throw FormatError("completion: " + std::to_string(size) + " bytes (expected 16)");
  }
  ByteReader r(data, size, "completion");
  if (r.u32("magic") != kCompletionMagic) throw FormatError("completion: wrong magic");
  Completion c;
  c.sequence = r.u32("sequence");
  c.word2 = r.u32("word2");
  c.word3 = r.u32("word3");
  return c;
}

std::vector<std::uint8_t> encode_completion(std::uint32_t sequence) {
  ByteWriter w;
  w.u32(kCompletionMagic);
  w.u32(sequence);
  w.u32(0);
  w.u32(0);
  return w.take();
}

bool looks_like_completion(const std::uint8_t* data, std::size_t size) {
  if (size != kCompletionBytes) return false;
  ByteReader r(data, size, "response");
  return r.u32("magic") == kCompletionMagic;
}

std::string FirmwareVersion::to_string() const {
  return std::to_string(major) + "." + std::to_string(minor) + "." + std::to_string(revision) + "." +
         std::to_string(build);
}

std::vector<FirmwareVersion> parse_firmware_versions(const std::uint8_t* data, std::size_t size) {
  if (size < 16) throw FormatError("firmware versions: " + std::to_string(size) + " bytes, need one 16-byte record");
  ByteReader r(data, size, "firmware versions");
  std::vector<FirmwareVersion> out;
  while (r.remaining() >= 16 && out.size() < 7) {
    FirmwareVersion v;
    const std::uint32_t maj_min = r.u32("maj_min");
    v.major = static_cast<std::uint16_t>(maj_min >> 16);
    v.minor = static_cast<std::uint16_t>(maj_min & 0xFFFF);
    v.revision = r.u32("revision");
    v.build = r.u32("build");
    r.u32("reserved");
    out.push_back(v);
  }
  return out;
}

std::string parse_serial(const std::uint8_t* data, std::size_t size) {
  std::string s;
  for (std::size_t i = 0; i < size; i += 2) {
    const std::uint8_t c = data[i];
    if (c == 0) break;
    if (c < 0x20 || c > 0x7E) throw FormatError("serial number: byte " + std::to_string(i) + " is not printable ASCII");
    s.push_back(static_cast<char>(c));
  }
  if (s.empty()) throw FormatError("serial number: empty");
  return s;
}

DepthParams parse_depth_params(const std::uint8_t* data, std::size_t size) {
  if (size < kDepthParamsBytes) {
    throw FormatError("depth parameters: " + std::to_string(size) + " bytes (need 92)");
  }
  ByteReader r(data, size, "depth parameters");
  DepthParams p;
  p.fx = f32(r, "fx");
  p.fy = f32(r, "fy");
  f32(r, "unused");
  p.cx = f32(r, "cx");
  p.cy = f32(r, "cy");
  p.k1 = f32(r, "k1");
  p.k2 = f32(r, "k2");
  p.p1 = f32(r, "p1");
  p.p2 = f32(r, "p2");
  p.k3 = f32(r, "k3");
  check_depth_params(p);
  return p;
}

void check_depth_params(const DepthParams& p) {
  for (float v : {p.fx, p.fy, p.cx, p.cy, p.k1, p.k2, p.p1, p.p2, p.k3}) {
    if (!std::isfinite(v)) throw FormatError("depth parameters: not finite");
  }
  if (!(p.fx > 0 && p.fy > 0 && p.cx > 0 && p.cx < 512 && p.cy > 0 && p.cy < 424)) {
    throw FormatError("depth parameters: focal lengths must be > 0 and the centre inside the image");
  }
  for (float v : {p.k1, p.k2, p.p1, p.p2, p.k3}) {
    if (!(std::fabs(v) <= 10.0f)) throw FormatError("depth parameters: a distortion coefficient beyond 10");
  }
}

std::vector<std::uint8_t> encode_depth_params(const DepthParams& p) {
  ByteWriter w;
  const auto put = [&](float v) {
    std::uint32_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    w.u32(bits);
  };
  for (float v : {p.fx, p.fy, 0.0f, p.cx, p.cy, p.k1, p.k2, p.p1, p.p2, p.k3}) put(v);
  for (int i = 0; i < 13; ++i) put(0.0f);
  return w.take();
}

std::vector<float> P0Tables::p0_rad() const {
  std::vector<float> out(3 * 512 * 424);
  for (std::size_t g = 0; g < 3; ++g) {
    for (std::size_t i = 0; i < raw[g].size(); ++i) {
      out[g * raw[g].size() + i] = static_cast<float>(-static_cast<double>(raw[g][i]) * kP0RadPerUnit);
    }
  }
  return out;
}

P0Tables parse_p0_tables(const std::uint8_t* data, std::size_t size) {
  if (size < kP0TablesBytes) {
    throw FormatError("P0 tables: " + std::to_string(size) + " bytes (need " + std::to_string(kP0TablesBytes) + ")");
  }
  P0Tables t;
  for (std::size_t k = 0; k < 3; ++k) {
    ByteReader r(data + kP0HeaderBytes + k * kP0BlockBytes, kP0BlockBytes, "P0 table " + std::to_string(k));
    r.u16("pad");
    t.raw[k].resize(512 * 424);
    for (auto& v : t.raw[k]) v = r.u16("value");
  }
  return t;
}

std::vector<std::uint8_t> encode_p0_tables(const P0Tables& t) {
  ByteWriter w;
  w.u32(kP0HeaderBytes);
  for (int i = 0; i < 2; ++i) w.u32(0);
  w.u32(static_cast<std::uint32_t>(kP0BlockBytes));
  for (int i = 0; i < 4; ++i) w.u32(0);
  for (std::size_t k = 0; k < 3; ++k) {
    if (t.raw[k].size() != 512 * 424) throw std::invalid_argument("P0 table must have 512 x 424 values");
    w.u16(0);
    for (std::uint16_t v : t.raw[k]) w.u16(v);
    w.u16(0);
  }
  return w.take();
}

std::uint16_t p0_table_value(double p0_rad) {
  constexpr double kTwoPi = 6.283185307179586476925286766559;
  double phase = std::fmod(-p0_rad, kTwoPi);  // P0 * unit = -p0, in [0, 2 pi)
  if (phase < 0) phase += kTwoPi;
  const double v = std::round(phase / kP0RadPerUnit);
  return static_cast<std::uint16_t>(std::min(v, 65535.0));
}

std::uint32_t parse_status(const std::uint8_t* data, std::size_t size) {
  if (size != 4) throw FormatError("status: " + std::to_string(size) + " bytes (expected 4)");
  ByteReader r(data, size, "status");
  return r.u32("status");
}

}  // namespace tofmat::kinect
