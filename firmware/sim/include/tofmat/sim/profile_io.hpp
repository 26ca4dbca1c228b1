// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Device profiles and material libraries as versioned JSON files
// (firmware/sim/data/devices/*.json, firmware/sim/data/materials/*.json).
// Unknown keys are errors (a typo must not silently fall back to a default).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "tofmat/sim/device.hpp"
#include "tofmat/sim/material.hpp"

namespace tofmat::sim {

// Version 2 added signal_scale, full_well, decode_offset_rad, harmonics above
// h = 7, range_ref_mm, saturation, and the double kind; version 1 files read
// with their defaults.
inline constexpr int kProfileFormatVersion = 2;
inline constexpr int kProfileOldestVersion = 1;
inline constexpr std::size_t kProfileMaxBytes = 4 * 1024 * 1024;

struct MaterialLibrary {
  std::string name;
  int version = kProfileFormatVersion;
  std::vector<Material> materials;
  const Material& find(const std::string& material) const;  // throws std::invalid_argument
};

// Parse/serialise. Parse errors are tofmat::FormatError naming the key.
DeviceProfile device_from_json(const std::string& text);
std::string device_to_json(const DeviceProfile& d);
MaterialLibrary library_from_json(const std::string& text);
std::string library_to_json(const MaterialLibrary& lib);
Material material_from_json(const std::string& text);
std::string material_to_json(const Material& m);

// Load by file path, or by name from `data_dir` (<data_dir>/devices/<name>.json,
// <data_dir>/materials/<name>.json).
DeviceProfile load_device(const std::string& name_or_path, const std::filesystem::path& data_dir);
MaterialLibrary load_library(const std::string& name_or_path, const std::filesystem::path& data_dir);

}  // namespace tofmat::sim
