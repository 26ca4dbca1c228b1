// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Reading and writing device profiles and material libraries as JSON, with unknown keys and bad versions refused.
#include "tofmat/sim/profile_io.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <set>
#include <stdexcept>

#include "tofmat/core/error.hpp"
#include "tofmat/core/file_io.hpp"

namespace tofmat::sim {
namespace {

using json = nlohmann::json;

[[noreturn]] void fail(const std::string& where, const std::string& msg) { throw FormatError(where + ": " + msg); }

void only_keys(const json& j, const std::string& where, const std::set<std::string>& allowed) {
  if (!j.is_object()) fail(where, "expected an object");
  for (const auto& [k, v] : j.items()) {
    if (!allowed.count(k)) fail(where, "unknown key '" + k + "'");
  }
}

double num(const json& j, const std::string& where, const char* key, double fallback) {
  if (!j.contains(key)) return fallback;
  const auto& v = j.at(key);
  if (!v.is_number()) fail(where + "." + key, "expected a number");
  const double x = v.get<double>();
  if (!std::isfinite(x)) fail(where + "." + key, "must be finite");
  return x;
}

// An integer-typed JSON number in [lo, hi] (never read through a double, so
// every bit of a 64-bit seed survives).
std::uint64_t integer(const json& j, const std::string& where, const char* key, std::uint64_t fallback,
                      std::uint64_t lo, std::uint64_t hi) {
  if (!j.contains(key)) return fallback;
  const auto& v = j.at(key);
  if (!v.is_number_integer() || (v.is_number_integer() && !v.is_number_unsigned() && v.get<std::int64_t>() < 0)) {
    fail(where + "." + key, "expected a non-negative integer");
  }
  const auto x = v.get<std::uint64_t>();
  if (x < lo || x > hi) fail(where + "." + key, "must be in " + std::to_string(lo) + ".." + std::to_string(hi));
  return x;
}

std::array<double, 3> triple(const json& j, const std::string& where, const char* key, std::array<double, 3> fallback) {
  if (!j.contains(key)) return fallback;
  const auto& v = j.at(key);
  if (!v.is_array() || v.size() != 3) fail(where + "." + key, "expected 3 numbers");
  std::array<double, 3> out{};
  for (std::size_t i = 0; i < 3; ++i) {
    if (!v[i].is_number()) fail(where + "." + key, "expected 3 numbers");
    out[i] = v[i].get<double>();
  }
  return out;
}

// A list of {h, amplitude, phase_rad} (h = 2..kMaxHarmonic) under key, into the arrays;
// absent: left as they are.
void harmonic_list(const json& f, const std::string& where, const char* key,
                   std::array<double, kMaxHarmonic + 1>& amplitude, std::array<double, kMaxHarmonic + 1>& phase) {
  if (!f.contains(key)) return;
  const std::string hw = where + "." + key;
  if (!f.at(key).is_array()) fail(hw, "expected a list");
  for (const json& h : f.at(key)) {
    only_keys(h, hw, {"h", "amplitude", "phase_rad"});
    const double order = num(h, hw, "h", 0);
    if (order != std::floor(order) || order < 2 || order > kMaxHarmonic) {
      fail(hw, "h must be an integer 2.." + std::to_string(kMaxHarmonic));
    }
    amplitude[static_cast<std::size_t>(order)] = num(h, hw, "amplitude", 0.0);
    phase[static_cast<std::size_t>(order)] = num(h, hw, "phase_rad", 0.0);
  }
}

std::string str(const json& j, const std::string& where, const char* key) {
  if (!j.contains(key) || !j.at(key).is_string()) fail(where + "." + key, "expected a string");
  return j.at(key).get<std::string>();
}

json parse(const std::string& text, const std::string& what) {
  if (text.size() > kProfileMaxBytes) fail(what, "larger than the 4 MiB limit");
  try {
    return json::parse(text);
  } catch (const json::parse_error& e) {
    fail(what, std::string("not valid JSON: ") + e.what());
  }
}

void check_version(const json& j, const std::string& where) {
  if (!j.contains("version")) fail(where, "missing version (this build reads versions 1 and 2)");
  const double v = num(j, where, "version", -1);
  if (!j.at("version").is_number_integer() || v < kProfileOldestVersion || v > kProfileFormatVersion) {
    fail(where, "unsupported version (this build reads versions 1 and 2)");
  }
}

Material material_from(const json& j, const std::string& where) {
  only_keys(j, where,
            {"name", "kind", "albedo", "subsurface", "tau_ps", "gamma_k", "refractive_index", "thickness_mm",
             "path_factor", "backing", "subsurface2", "tau2_ps", "noise_mm", "fit", "notes"});
  Material m;
  m.name = str(j, where, "name");
  try {
    m.kind = response_kind_from_name(str(j, where, "kind"));
  } catch (const std::invalid_argument& e) {
    fail(where + ".kind", e.what());
  }
  m.albedo = num(j, where, "albedo", m.albedo);
  m.subsurface = num(j, where, "subsurface", m.subsurface);
  m.tau_ps = num(j, where, "tau_ps", m.tau_ps);
  m.gamma_k = num(j, where, "gamma_k", m.gamma_k);
  m.refractive_index = num(j, where, "refractive_index", m.refractive_index);
  m.thickness_mm = num(j, where, "thickness_mm", m.thickness_mm);
  m.path_factor = num(j, where, "path_factor", m.path_factor);
  m.backing = num(j, where, "backing", m.backing);
  m.subsurface2 = num(j, where, "subsurface2", m.subsurface2);
  m.tau2_ps = num(j, where, "tau2_ps", m.tau2_ps);
  m.noise_mm = num(j, where, "noise_mm", m.noise_mm);
  try {
    m.validate();
  } catch (const std::invalid_argument& e) {
    fail(where, e.what());
  }
  return m;
}

json material_to(const Material& m) {
  return json{{"name", m.name},
              {"kind", response_kind_name(m.kind)},
              {"albedo", m.albedo},
              {"subsurface", m.subsurface},
              {"tau_ps", m.tau_ps},
              {"gamma_k", m.gamma_k},
              {"refractive_index", m.refractive_index},
              {"thickness_mm", m.thickness_mm},
              {"path_factor", m.path_factor},
              {"backing", m.backing},
              {"subsurface2", m.subsurface2},
              {"tau2_ps", m.tau2_ps},
              {"noise_mm", m.noise_mm}};
}

std::string read_text(const std::filesystem::path& p) {
  const auto bytes = read_file_bounded(p, kProfileMaxBytes);
  return std::string(bytes.begin(), bytes.end());
}

std::filesystem::path resolve(const std::string& name_or_path, const std::filesystem::path& dir) {
  std::filesystem::path p(name_or_path);
  if (p.has_extension() || p.has_parent_path()) return p;
  return dir / (name_or_path + ".json");
}

}  // namespace

MaterialLibrary library_from(const std::string& text);

DeviceProfile device_from(const std::string& text) {
  const json j = parse(text, "device profile");
  const std::string w = "device";
  only_keys(j, w,
            {"name", "version", "range_ref_mm", "saturation", "frequencies", "pixel_phase", "noise", "signal", "camera",
             "fit", "notes"});
  check_version(j, w);
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.name = str(j, w, "name");
  d.range_ref_mm = num(j, w, "range_ref_mm", d.range_ref_mm);
  if (j.contains("saturation")) {
    only_keys(j.at("saturation"), w + ".saturation", {"sharpness"});
    d.saturation_sharpness = num(j.at("saturation"), w + ".saturation", "sharpness", d.saturation_sharpness);
  }
  if (!j.contains("frequencies") || !j.at("frequencies").is_array() || j.at("frequencies").size() != 3) {
    fail(w + ".frequencies", "expected 3 entries (groups 80, 16, 120 MHz)");
  }
  for (std::size_t g = 0; g < 3; ++g) {
    const json& f = j.at("frequencies")[g];
    const std::string fw = w + ".frequencies[" + std::to_string(g) + "]";
    only_keys(f, fw,
              {"freq_mhz", "signal_scale", "full_well", "scale_error", "phase_offset_rad", "decode_offset_rad",
               "harmonics", "session_drift", "step_gain", "step_offset"});
    auto& m = d.groups[g];
    m.freq_mhz = num(f, fw, "freq_mhz", 0.0);
    m.signal_scale = num(f, fw, "signal_scale", m.signal_scale);
    m.decode_offset_rad = num(f, fw, "decode_offset_rad", 0.0);
    // null (or absent): the taps never saturate
    if (f.contains("full_well") && !f.at("full_well").is_null()) m.full_well = num(f, fw, "full_well", 0.0);
    m.scale_error = num(f, fw, "scale_error", 0.0);
    m.phase_offset_rad = num(f, fw, "phase_offset_rad", 0.0);
    m.step_gain = triple(f, fw, "step_gain", m.step_gain);
    m.step_offset = triple(f, fw, "step_offset", m.step_offset);
    harmonic_list(f, fw, "harmonics", m.harmonic_amplitude, m.harmonic_phase_rad);
    harmonic_list(f, fw, "session_drift", m.drift_amplitude, m.drift_phase_rad);
  }
  if (j.contains("pixel_phase")) {
    const json& p = j.at("pixel_phase");
    const std::string pw = w + ".pixel_phase";
    only_keys(p, pw, {"mean_rad", "radial_rad", "scatter_rad", "seed"});
    d.pixel_phase.mean_rad = triple(p, pw, "mean_rad", d.pixel_phase.mean_rad);
    d.pixel_phase.radial_rad = triple(p, pw, "radial_rad", d.pixel_phase.radial_rad);
    d.pixel_phase.scatter_rad = num(p, pw, "scatter_rad", 0.0);
    d.pixel_phase.seed = integer(p, pw, "seed", 1, 0, UINT64_MAX);
  }
  if (j.contains("noise")) {
    const json& n = j.at("noise");
    only_keys(n, w + ".noise", {"read_noise", "shot_gain", "ambient"});
    d.noise.read_noise = num(n, w + ".noise", "read_noise", 0.0);
    d.noise.shot_gain = num(n, w + ".noise", "shot_gain", 0.0);
    d.noise.ambient = num(n, w + ".noise", "ambient", 0.0);
  }
  if (j.contains("signal")) {
    const json& s = j.at("signal");
    only_keys(s, w + ".signal", {"counts_at_1m", "saturation"});
    d.signal.counts_at_1m = num(s, w + ".signal", "counts_at_1m", d.signal.counts_at_1m);
    d.signal.saturation = num(s, w + ".signal", "saturation", d.signal.saturation);
  }
  if (j.contains("camera")) {
    const json& c = j.at("camera");
    only_keys(c, w + ".camera", {"width", "height", "fx", "fy", "cx", "cy"});
    d.camera.width = static_cast<int>(integer(c, w + ".camera", "width", 512, 1, 4096));
    d.camera.height = static_cast<int>(integer(c, w + ".camera", "height", 424, 1, 4096));
    d.camera.fx = num(c, w + ".camera", "fx", d.camera.fx);
    d.camera.fy = num(c, w + ".camera", "fy", d.camera.fy);
    d.camera.cx = num(c, w + ".camera", "cx", d.camera.cx);
    d.camera.cy = num(c, w + ".camera", "cy", d.camera.cy);
  }
  try {
    d.validate();
  } catch (const std::invalid_argument& e) {
    fail(w, e.what());
  }
  return d;
}

std::string device_to_json(const DeviceProfile& d) {
  json freqs = json::array();
  for (const auto& f : d.groups) {
    json drift = json::array();
    for (int h = 2; h <= kMaxHarmonic; ++h) {
      const auto k = static_cast<std::size_t>(h);
      if (f.drift_amplitude[k] != 0.0) {
        drift.push_back({{"h", h}, {"amplitude", f.drift_amplitude[k]}, {"phase_rad", f.drift_phase_rad[k]}});
      }
    }
    json hs = json::array();
    // h = 2..7 always, higher orders up to the last non-zero one.
    int top = 7;
    for (int h = 8; h <= kMaxHarmonic; ++h) {
      if (f.harmonic_amplitude[static_cast<std::size_t>(h)] != 0.0) top = h;
    }
    for (int h = 2; h <= top; ++h) {
      const auto k = static_cast<std::size_t>(h);
      hs.push_back({{"h", h}, {"amplitude", f.harmonic_amplitude[k]}, {"phase_rad", f.harmonic_phase_rad[k]}});
    }
    freqs.push_back({{"freq_mhz", f.freq_mhz},
                     {"signal_scale", f.signal_scale},
                     {"full_well", std::isfinite(f.full_well) ? json(f.full_well) : json(nullptr)},
                     {"scale_error", f.scale_error},
                     {"phase_offset_rad", f.phase_offset_rad},
                     {"decode_offset_rad", f.decode_offset_rad},
                     {"harmonics", hs},
                     {"step_gain", f.step_gain},
                     {"step_offset", f.step_offset}});
    if (!drift.empty()) freqs.back()["session_drift"] = drift;
  }
  const json j{
      {"name", d.name},
      {"version", kProfileFormatVersion},
      {"range_ref_mm", d.range_ref_mm},
      {"saturation", {{"sharpness", d.saturation_sharpness}}},
      {"frequencies", freqs},
      {"pixel_phase",
       {{"mean_rad", d.pixel_phase.mean_rad},
        {"radial_rad", d.pixel_phase.radial_rad},
        {"scatter_rad", d.pixel_phase.scatter_rad},
        {"seed", d.pixel_phase.seed}}},
      {"noise", {{"read_noise", d.noise.read_noise}, {"shot_gain", d.noise.shot_gain}, {"ambient", d.noise.ambient}}},
      {"signal", {{"counts_at_1m", d.signal.counts_at_1m}, {"saturation", d.signal.saturation}}},
      {"camera",
       {{"width", d.camera.width},
        {"height", d.camera.height},
        {"fx", d.camera.fx},
        {"fy", d.camera.fy},
        {"cx", d.camera.cx},
        {"cy", d.camera.cy}}}};
  return j.dump(2);
}

// Any JSON error the checks above did not anticipate still becomes a FormatError.
template <typename F>
auto guarded(const char* what, F&& f) {
  try {
    return f();
  } catch (const json::exception& e) {
    throw FormatError(std::string(what) + ": " + e.what());
  }
}

DeviceProfile device_from_json(const std::string& text) {
  return guarded("device profile", [&] { return device_from(text); });
}
MaterialLibrary library_from_json(const std::string& text) {
  return guarded("material library", [&] { return library_from(text); });
}
Material material_from_json(const std::string& text) {
  return guarded("material", [&] { return material_from(parse(text, "material"), "material"); });
}
std::string material_to_json(const Material& m) { return material_to(m).dump(2); }

MaterialLibrary library_from(const std::string& text) {
  const json j = parse(text, "material library");
  const std::string w = "library";
  only_keys(j, w, {"name", "version", "materials", "device", "fit", "notes"});
  check_version(j, w);
  MaterialLibrary lib;
  lib.name = str(j, w, "name");
  if (!j.contains("materials") || !j.at("materials").is_array() || j.at("materials").empty()) {
    fail(w + ".materials", "expected a non-empty list");
  }
  std::set<std::string> seen;
  for (std::size_t i = 0; i < j.at("materials").size(); ++i) {
    Material m = material_from(j.at("materials")[i], w + ".materials[" + std::to_string(i) + "]");
    if (!seen.insert(m.name).second) fail(w + ".materials", "duplicate material '" + m.name + "'");
    lib.materials.push_back(std::move(m));
  }
  return lib;
}

std::string library_to_json(const MaterialLibrary& lib) {
  json mats = json::array();
  for (const auto& m : lib.materials) mats.push_back(material_to(m));
  return json{{"name", lib.name}, {"version", kProfileFormatVersion}, {"materials", mats}}.dump(2);
}

const Material& MaterialLibrary::find(const std::string& material) const {
  for (const auto& m : materials) {
    if (m.name == material) return m;
  }
  throw std::invalid_argument("material '" + material + "' is not in library '" + name + "'");
}

DeviceProfile load_device(const std::string& name_or_path, const std::filesystem::path& data_dir) {
  const auto p = resolve(name_or_path, data_dir / "devices");
  try {
    return device_from_json(read_text(p));
  } catch (const FormatError& e) {
    throw FormatError(p.string() + ": " + e.what());
  }
}

MaterialLibrary load_library(const std::string& name_or_path, const std::filesystem::path& data_dir) {
  const auto p = resolve(name_or_path, data_dir / "materials");
  try {
    return library_from_json(read_text(p));
  } catch (const FormatError& e) {
    throw FormatError(p.string() + ": " + e.what());
  }
}

}  // namespace tofmat::sim
