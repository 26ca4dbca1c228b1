// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Encoding, decoding (with every bound and the CRC-32 checked), saving and loading of .tmx table files.
#include "tofmat/core/table_file.hpp"

#include <zlib.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <string>

#include "tofmat/core/byte_reader.hpp"
#include "tofmat/core/byte_writer.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/core/file_io.hpp"

namespace tofmat {
namespace {

[[noreturn]] void fail(const std::string& msg) { throw FormatError("table file: " + msg); }

std::uint32_t crc32_of(const std::uint8_t* p, std::size_t n) {
  uLong c = crc32(0L, Z_NULL, 0);
  // zlib takes uInt lengths; feed in chunks so any size is safe.
  while (n > 0) {
    const uInt chunk = static_cast<uInt>(std::min<std::size_t>(n, 1u << 30));
    c = crc32(c, p, chunk);
    p += chunk;
    n -= chunk;
  }
  return static_cast<std::uint32_t>(c);
}

// 1.3's calibration block (docs/table-format.md).
void write_calibration(ByteWriter& w, const TableCalibration& c) {
  w.u16(static_cast<std::uint16_t>(c.offset_sd_mm.size()));
  for (double v : c.offset_sd_mm) w.f64(v);
  for (double v : {c.drift1_sd_mm, c.drift2_sd_mm, c.noise_scale, c.floor_mm, c.huber_k}) w.f64(v);
  w.u32(c.iterations);
  w.u8(static_cast<std::uint8_t>(c.methods.size()));
  for (const MethodCalibration& m : c.methods) {
    w.u8(static_cast<std::uint8_t>(m.method.size()));
    w.bytes(m.method);
    for (const auto* knots : {&m.temperatures, &m.unknown_fits}) {
      w.u16(static_cast<std::uint16_t>(knots->size()));
      for (const auto& [bins, v] : *knots) {
        w.f64(bins);
        w.f64(v);
      }
    }
  }
}

constexpr std::size_t kMaxMethodNameBytes = 16;
constexpr std::size_t kMaxCalibrationMethods = 8;

TableCalibration read_calibration(ByteReader& in, std::uint32_t n_rows) {
  TableCalibration c;
  const std::uint16_t n_offsets = in.u16("calibration offset count");
  if (n_offsets != n_rows)
    fail("calibration holds " + std::to_string(n_offsets) + " row offsets for " + std::to_string(n_rows) + " rows");
  c.offset_sd_mm.resize(n_offsets);
  for (double& v : c.offset_sd_mm) v = in.f64("calibration offset sd");
  c.drift1_sd_mm = in.f64("calibration drift");
  c.drift2_sd_mm = in.f64("calibration drift");
  c.noise_scale = in.f64("calibration noise scale");
  c.floor_mm = in.f64("calibration noise floor");
  c.huber_k = in.f64("calibration huber k");
  c.iterations = in.u32("calibration iterations");
  const std::uint8_t n_methods = in.u8("calibration method count");
  if (n_methods > kMaxCalibrationMethods) fail("calibration method count " + std::to_string(n_methods) + " is over 8");
  c.methods.resize(n_methods);
  for (MethodCalibration& m : c.methods) {
    const std::uint8_t len = in.u8("calibration method name length");
    if (len == 0 || len > kMaxMethodNameBytes)
      fail("calibration method name length " + std::to_string(len) + " is outside 1..16");
    m.method.assign(reinterpret_cast<const char*>(in.take(len, "calibration method name")), len);
    for (auto* knots : {&m.temperatures, &m.unknown_fits}) {
      const std::uint16_t n = in.u16("calibration knot count");
      if (n > kMaxCalibrationKnots) fail("calibration knot count " + std::to_string(n) + " is over 64");
      knots->resize(n);
      for (auto& [bins, v] : *knots) {
        bins = in.f64("calibration knot");
        v = in.f64("calibration knot");
      }
    }
  }
  return c;
}

}  // namespace

double choose_quant_step_mm(const ExemplarTable& table) {
  double max_abs = 0.0;
  for (float v : table.values()) {
    if (!std::isnan(v)) max_abs = std::max(max_abs, static_cast<double>(std::fabs(v)));
  }
  // Smallest 2^e (e >= -24) with round(max_abs / 2^e) <= 32767 whose rounded
  // values still decode to finite floats (near FLT_MAX rounding can reach 2^128).
  for (int e = -24; e < 1000; ++e) {
    const double step = std::ldexp(1.0, e);
    const double q = std::nearbyint(max_abs / step);
    if (q <= kTableMaxAbs && q * step <= static_cast<double>(FLT_MAX)) return step;
  }
  return std::ldexp(1.0, 1000);  // unreachable for finite float values
}

std::vector<std::uint8_t> encode_table(const ExemplarTable& table) {
  const double step = choose_quant_step_mm(table);
  ByteWriter w;
  w.bytes(std::string_view(kTableMagic, sizeof kTableMagic));
  w.u16(kTableVersionMajor);
  const auto& distortion = table.distortion();
  const auto& calibration = table.calibration();
  // The oldest minor that holds what the table carries (older readers still read it).
  w.u16(calibration         ? std::uint16_t{3}
        : distortion        ? std::uint16_t{2}
        : table.has_noise() ? std::uint16_t{1}
                            : std::uint16_t{0});
  w.u32(static_cast<std::uint32_t>(table.n_materials()));
  w.u32(table.n_rows());
  w.u32(table.n_bins());
  w.f64(table.bins().start_mm);
  w.f64(table.bins().width_mm);
  w.f64(step);
  for (const RowSpec& r : table.rows()) {
    w.u16(r.freq_mhz);
    w.u16(r.ref_freq_mhz);
  }
  for (const std::string& name : table.materials()) {
    w.u8(static_cast<std::uint8_t>(name.size()));
    w.bytes(name);
  }
  for (float v : table.values()) {
    const std::int16_t q =
        std::isnan(v) ? kTableMissing : static_cast<std::int16_t>(std::nearbyint(static_cast<double>(v) / step));
    w.u16(static_cast<std::uint16_t>(q));
  }
  if (distortion || calibration) {
    // 1.2 and 1.3: the noise block always (NaN: none), then the distortion's
    // grid and values (1.3: a grid of count 0 when there is none).
    if (table.has_noise()) {
      for (float s : table.noise_mm()) w.f32(s);
    } else {
      for (std::size_t i = 0; i < table.n_materials() * table.n_rows(); ++i) w.f32(NAN);
    }
    w.f64(distortion ? distortion->grid.start_mm : 0.0);
    w.f64(distortion ? distortion->grid.width_mm : 0.0);
    w.u32(distortion ? distortion->grid.count : 0);
    if (distortion)
      for (float v : distortion->mm) w.f32(v);
    if (calibration) write_calibration(w, *calibration);
  } else {
    for (float s : table.noise_mm()) w.f32(s);  // 1.1's noise block
  }
  const std::uint32_t crc = crc32_of(w.data().data(), w.data().size());
  w.u32(crc);
  return w.take();
}

ExemplarTable decode_table(const std::uint8_t* bytes, std::size_t size) {
  if (size > kTableMaxFileBytes) fail("file is larger than the " + std::to_string(kTableMaxFileBytes) + "-byte limit");
  ByteReader in(bytes, size, "table file");
  if (std::memcmp(in.take(sizeof kTableMagic, "magic"), kTableMagic, sizeof kTableMagic) != 0) {
    fail("bad magic (not a tofmat table file)");
  }
  const std::uint16_t major = in.u16("version");
  const std::uint16_t minor = in.u16("version");
  if (major != kTableVersionMajor || minor > kTableVersionMinor) {
    fail("unsupported version " + std::to_string(major) + "." + std::to_string(minor) + " (this build reads " +
         std::to_string(kTableVersionMajor) + "." + std::to_string(kTableVersionMinor) + ")");
  }
  const std::uint32_t n_materials = in.u32("material count");
  const std::uint32_t n_rows = in.u32("row count");
  const std::uint32_t n_bins = in.u32("bin count");
  if (n_materials < 1 || n_materials > kMaxMaterials) {
    fail("material count " + std::to_string(n_materials) + " is outside 1.." + std::to_string(kMaxMaterials));
  }
  if (n_rows < 1 || n_rows > kMaxRows) fail("row count " + std::to_string(n_rows) + " is outside 1..16");
  if (n_bins < 1 || n_bins > kMaxBins) fail("bin count " + std::to_string(n_bins) + " is outside 1..65535");
  const std::size_t n_values = std::size_t{n_materials} * n_rows * n_bins;
  if (n_values * 2 > kTableMaxFileBytes) fail("dimensions describe a table larger than the file size limit");

  BinSpec bins;
  bins.start_mm = in.f64("bin start");
  bins.width_mm = in.f64("bin width");
  bins.count = n_bins;
  const double step = in.f64("quantisation step");
  if (!std::isfinite(step) || !(step > 0.0)) fail("quantisation step is not a finite positive number");

  std::vector<RowSpec> rows(n_rows);
  for (auto& r : rows) {
    r.freq_mhz = in.u16("row frequency");
    r.ref_freq_mhz = in.u16("row reference frequency");
  }
  std::vector<std::string> names(n_materials);
  for (auto& name : names) {
    const std::uint8_t len = in.u8("name length");
    if (len == 0 || len > kMaxNameBytes) fail("material name length " + std::to_string(len) + " is outside 1..64");
    const auto* p = in.take(len, "material name");
    name.assign(reinterpret_cast<const char*>(p), len);
  }
  const std::size_t n_noise = minor >= 1 ? std::size_t{n_materials} * n_rows : 0;
  constexpr std::size_t kGridBytes = 8 + 8 + 4;  // 1.2: the distortion grid's start, width and count
  const std::size_t fixed_rest = n_values * 2 + n_noise * 4 + (minor >= 2 ? kGridBytes : 0) + 4;
  if (in.remaining() < fixed_rest) {
    fail("truncated: " + std::to_string(in.remaining()) + " bytes left for values, noise" +
         (minor >= 2 ? ", distortion" : "") + " and checksum, need " + std::to_string(fixed_rest));
  }
  if (minor < 2 && in.remaining() > fixed_rest) {
    fail(std::to_string(in.remaining() - fixed_rest) + " unexpected trailing bytes");
  }
  const std::uint8_t* raw = in.take(n_values * 2, "values");
  std::vector<float> noise(n_noise);
  for (float& x : noise) x = in.f32("noise");
  // 1.2 always has the noise block: all NaN stands for no noise.
  if (minor >= 2 && std::all_of(noise.begin(), noise.end(), [](float x) { return std::isnan(x); })) noise.clear();
  std::optional<DepthDistortion> distortion;
  if (minor >= 2) {
    DepthDistortion d;
    d.grid.start_mm = in.f64("distortion grid start");
    d.grid.width_mm = in.f64("distortion grid width");
    d.grid.count = in.u32("distortion grid count");
    // (1.3 writes a grid of count 0 for a table without a distortion.)
    const bool none = minor >= 3 && d.grid.count == 0;
    if (!none && (d.grid.count < 1 || d.grid.count > kMaxBins))
      fail("distortion grid count " + std::to_string(d.grid.count) + " is outside 1..65535");
    const std::size_t n_distortion = std::size_t{n_materials} * d.grid.count;
    const std::size_t rest = n_distortion * 4 + 4;
    if (in.remaining() < rest) {
      fail("truncated: " + std::to_string(in.remaining()) + " bytes left for the distortion and checksum, need " +
           std::to_string(rest));
    }
    if (minor < 3 && in.remaining() > rest) fail(std::to_string(in.remaining() - rest) + " unexpected trailing bytes");
    d.mm.resize(n_distortion);
    for (float& x : d.mm) x = in.f32("distortion");
    if (!none) distortion = std::move(d);
  }
  std::optional<TableCalibration> calibration;
  if (minor >= 3) {
    calibration = read_calibration(in, n_rows);
    if (in.remaining() < 4) fail("truncated: no checksum after the calibration");
    if (in.remaining() > 4) fail(std::to_string(in.remaining() - 4) + " unexpected trailing bytes");
  }
  const std::size_t crc_offset = in.offset();
  const std::uint32_t stored_crc = in.u32("checksum");
  const std::uint32_t actual_crc = crc32_of(bytes, crc_offset);
  if (stored_crc != actual_crc) fail("checksum mismatch: the file is corrupted");

  std::vector<float> values(n_values);
  for (std::size_t i = 0; i < n_values; ++i) {
    const auto q = static_cast<std::int16_t>(static_cast<std::uint16_t>(raw[2 * i] | (raw[2 * i + 1] << 8)));
    if (q == kTableMissing) {
      values[i] = NAN;
      continue;
    }
    const double v = q * step;
    if (std::fabs(v) > static_cast<double>(FLT_MAX))
      fail("a value times the quantisation step exceeds the float range");
    values[i] = static_cast<float>(v);
  }
  try {
    return ExemplarTable(std::move(names), std::move(rows), bins, std::move(values), step, std::move(noise))
        .with_distortion(std::move(distortion))
        .with_calibration(std::move(calibration));
  } catch (const std::invalid_argument& e) {
    fail(std::string("inconsistent content: ") + e.what());
  }
}

void save_table(const ExemplarTable& table, const std::filesystem::path& path) {
  write_file_atomic(path, encode_table(table));
}

ExemplarTable load_table(const std::filesystem::path& path) {
  const auto bytes = read_file_bounded(path, kTableMaxFileBytes);
  try {
    return decode_table(bytes.data(), bytes.size());
  } catch (const FormatError& e) {
    throw FormatError(path.string() + ": " + e.what());
  }
}

}  // namespace tofmat
