// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// ExemplarTable: construction with its checks, lookups, and loading the real database's folder of .npy files.
#include "tofmat/core/exemplar_table.hpp"

#include <algorithm>
#include <cerrno>
#include <cfloat>
#include <cmath>
#include <set>
#include <stdexcept>

#include "tofmat/core/error.hpp"
#include "tofmat/core/npy.hpp"

namespace tofmat {

std::vector<RowSpec> kinect2_database_rows() { return {{16, 120}, {80, 120}}; }

std::string exemplar_material(const std::string& name) { return name.substr(0, name.find('@')); }

void validate_material_name(const std::string& name) {
  if (name.empty() || name.size() > kMaxNameBytes) {
    throw std::invalid_argument("material name must be 1.." + std::to_string(kMaxNameBytes) + " bytes: '" + name + "'");
  }
  for (char c : name) {
    if (c <= 0x20 || c >= 0x7f) {
      throw std::invalid_argument("material name must be printable ASCII without spaces: '" + name + "'");
    }
  }
  // The label of a query that fits no material (confidence.hpp's kUnknownLabel).
  if (name == "unknown") throw std::invalid_argument("material name 'unknown' is reserved for open-set rejection");
  const std::size_t at = name.find('@');
  if (at == std::string::npos) return;
  if (at == 0 || at + 1 == name.size() || name.find('@', at + 1) != std::string::npos)
    throw std::invalid_argument("an exemplar's name is MATERIAL@TAG, one '@' between two non-empty parts: '" + name +
                                "'");
  if (name.compare(0, at, "unknown") == 0 && at == 7)
    throw std::invalid_argument("material name 'unknown' is reserved for open-set rejection: '" + name + "'");
}

ExemplarTable::ExemplarTable(std::vector<std::string> materials, std::vector<RowSpec> rows, BinSpec bins,
                             std::vector<float> values, double quant_step_mm, std::vector<float> noise_mm)
    : materials_(std::move(materials)),
      rows_(std::move(rows)),
      bins_(bins),
      values_(std::move(values)),
      quant_step_mm_(quant_step_mm),
      noise_mm_(std::move(noise_mm)) {
  if (materials_.empty()) throw std::invalid_argument("an exemplar table needs at least one material");
  if (materials_.size() > kMaxMaterials) {
    throw std::invalid_argument("too many materials: " + std::to_string(materials_.size()) + " (limit " +
                                std::to_string(kMaxMaterials) + ")");
  }
  if (rows_.empty() || rows_.size() > kMaxRows) {
    throw std::invalid_argument("an exemplar table needs 1.." + std::to_string(kMaxRows) + " rows, got " +
                                std::to_string(rows_.size()));
  }
  bins_.validate();
  std::set<std::string> seen;
  for (const auto& name : materials_) {
    validate_material_name(name);
    if (!seen.insert(name).second) throw std::invalid_argument("duplicate material name '" + name + "'");
    std::string material = exemplar_material(name);
    const auto it = std::find(distinct_.begin(), distinct_.end(), material);
    material_ids_.push_back(static_cast<std::uint32_t>(it - distinct_.begin()));
    if (it == distinct_.end()) distinct_.push_back(std::move(material));
  }
  const std::size_t expected = materials_.size() * elements_per_material();
  if (values_.size() != expected) {
    throw std::invalid_argument("values hold " + std::to_string(values_.size()) + " elements, expected " +
                                std::to_string(expected) + " (materials x rows x bins)");
  }
  for (float v : values_) {
    if (std::isinf(v)) throw std::invalid_argument("table values must be finite or NaN (missing), found Inf");
  }
  if (!std::isfinite(quant_step_mm_) || quant_step_mm_ < 0.0) {
    throw std::invalid_argument("quantisation step must be finite and >= 0");
  }
  if (!noise_mm_.empty() && noise_mm_.size() != materials_.size() * rows_.size()) {
    throw std::invalid_argument("noise holds " + std::to_string(noise_mm_.size()) + " values, expected " +
                                std::to_string(materials_.size() * rows_.size()) + " (materials x rows)");
  }
  for (float s : noise_mm_) {
    if (!std::isnan(s) && !(std::isfinite(s) && s > 0.0f)) {
      throw std::invalid_argument("a material's bin noise must be finite and > 0 mm, or NaN (not measured)");
    }
  }
}

ExemplarTable ExemplarTable::with_noise(std::vector<float> noise_mm) const {
  ExemplarTable t(materials_, rows_, bins_, values_, quant_step_mm_, std::move(noise_mm));
  t.distortion_ = distortion_;
  t.calibration_ = calibration_;
  return t;
}

ExemplarTable ExemplarTable::with_calibration(std::optional<TableCalibration> c) const {
  if (c) c->validate(n_rows());
  ExemplarTable t = *this;
  t.calibration_ = std::move(c);
  return t;
}

const MethodCalibration* TableCalibration::method(const std::string& name) const {
  for (const auto& m : methods)
    if (m.method == name) return &m;
  return nullptr;
}

ExemplarTable ExemplarTable::with_distortion(std::optional<DepthDistortion> d) const {
  if (d) {
    d->grid.validate();
    const std::size_t expected = materials_.size() * d->grid.count;
    if (d->mm.size() != expected) {
      throw std::invalid_argument("depth distortion holds " + std::to_string(d->mm.size()) + " values, expected " +
                                  std::to_string(expected) + " (materials x grid samples)");
    }
    for (float v : d->mm) {
      if (!std::isnan(v) && !(std::fabs(v) <= kMaxDistortionMm)) {
        throw std::invalid_argument("a depth distortion must be NaN (unknown) or finite and at most 10000 mm in size");
      }
    }
  }
  ExemplarTable t = *this;
  t.distortion_ = std::move(d);
  return t;
}

double ExemplarTable::distortion_mm(std::size_t m, double measured_mm) const {
  if (!distortion_ || m >= materials_.size() || !std::isfinite(measured_mm)) return NAN;
  const BinSpec& g = distortion_->grid;
  // Position among the samples (sample j at the centre of bin j).
  const double p = (measured_mm - g.start_mm) / g.width_mm - 0.5;
  if (!(p >= 0.0) || p > static_cast<double>(g.count - 1)) return NAN;
  const auto j = static_cast<std::uint32_t>(p);
  const float* row = distortion_->mm.data() + m * g.count;
  if (j + 1 >= g.count) return row[j];  // (p is exactly the last sample)
  const double f = p - j;
  return (1.0 - f) * row[j] + f * row[j + 1];  // NaN next to an unknown sample
}

std::size_t ExemplarTable::valid_count(std::size_t m) const {
  const float* v = material_values(m);
  return static_cast<std::size_t>(
      std::count_if(v, v + elements_per_material(), [](float x) { return !std::isnan(x); }));
}

std::int64_t ExemplarTable::index_of(const std::string& name) const {
  const auto it = std::find(materials_.begin(), materials_.end(), name);
  return it == materials_.end() ? -1 : static_cast<std::int64_t>(it - materials_.begin());
}

ExemplarTable ExemplarTable::from_npy_dir(const std::filesystem::path& dir, double bin_start_mm, double bin_stop_mm,
                                          std::vector<RowSpec> rows) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    const bool exists = std::filesystem::exists(dir, ec);
    throw IoError((exists ? "not a directory: " : "no such directory: ") + dir.string(), exists ? ENOTDIR : ENOENT);
  }
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.is_regular_file() && entry.path().extension() == ".npy") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) throw IoError("no .npy files in " + dir.string(), ENOENT);
  if (files.size() > kMaxMaterials)
    throw std::invalid_argument(std::to_string(files.size()) + " .npy files in " + dir.string() +
                                ": a table holds at most " + std::to_string(kMaxMaterials) + " materials");
  std::uintmax_t total = 0;
  for (const auto& f : files) total += std::filesystem::file_size(f);  // (throws if it cannot tell)
  if (total > kMaxTableFolderBytes)
    throw std::invalid_argument(dir.string() + ": its .npy files hold " + std::to_string(total >> 20) +
                                " MiB, more than " + std::to_string(kMaxTableFolderBytes >> 20) + " MiB");

  std::vector<std::string> names;
  std::vector<float> values;
  std::size_t n_rows = 0, n_bins = 0;
  for (const auto& f : files) {
    const NpyArray a = read_npy_file(f);
    if (a.shape.size() != 2) {
      throw FormatError(f.string() + ": expected a 2-D array (rows x bins), got " + std::to_string(a.shape.size()) +
                        " dimensions");
    }
    if (names.empty()) {
      n_rows = a.shape[0];
      n_bins = a.shape[1];
    } else if (a.shape[0] != n_rows || a.shape[1] != n_bins) {
      throw FormatError(f.string() + ": shape (" + std::to_string(a.shape[0]) + ", " + std::to_string(a.shape[1]) +
                        ") differs from the other files' (" + std::to_string(n_rows) + ", " + std::to_string(n_bins) +
                        ")");
    }
    names.push_back(f.stem().string());
    const std::size_t base = values.size();
    values.resize(base + n_rows * n_bins);
    for (std::size_t b = 0; b < n_bins; ++b) {
      bool all_zero = true;
      for (std::size_t r = 0; r < n_rows; ++r) all_zero = all_zero && a.data[r * n_bins + b] == 0.0;
      for (std::size_t r = 0; r < n_rows; ++r) {
        const double v = a.data[r * n_bins + b];
        if (std::isinf(v)) throw FormatError(f.string() + ": holds an infinite value");
        if (std::fabs(v) > static_cast<double>(FLT_MAX))
          throw FormatError(f.string() + ": holds a value beyond the float32 range");
        values[base + r * n_bins + b] = all_zero ? NAN : static_cast<float>(v);
      }
    }
  }
  if (rows.empty()) rows = n_rows == 2 ? kinect2_database_rows() : std::vector<RowSpec>(n_rows);
  if (rows.size() != n_rows) {
    throw std::invalid_argument("row descriptions given for " + std::to_string(rows.size()) + " rows, files have " +
                                std::to_string(n_rows));
  }
  if (n_bins < 2 || n_bins > kMaxBins)
    throw FormatError(dir.string() + ": files hold " + std::to_string(n_bins) + " bins, need 2..65535");
  const BinSpec bins = BinSpec::linspace(bin_start_mm, bin_stop_mm, static_cast<std::uint32_t>(n_bins));
  ExemplarTable table(std::move(names), std::move(rows), bins, std::move(values));
  std::vector<std::string> sources;
  sources.reserve(files.size());
  for (const auto& f : files) sources.push_back(f.string());
  check_measured(table, dir.string(), sources);
  return table;
}

void check_measured(const ExemplarTable& table, const std::string& source,
                    const std::vector<std::string>& material_files, bool rows_must_vary) {
  for (std::size_t m = 0; m < table.n_materials(); ++m) {
    const std::string where =
        (m < material_files.size() ? material_files[m] : source) + ": material \"" + table.materials()[m] + "\" ";
    if (table.valid_count(m) == 0)
      throw FormatError(where +
                        "has no measured value (every bin is NaN, or 0 in every row: the database's mark "
                        "for a bin never measured)");
    for (std::uint32_t r = 0; rows_must_vary && r < table.n_rows(); ++r) {
      const float* v = table.material_values(m) + static_cast<std::size_t>(r) * table.n_bins();
      float first = NAN;
      std::size_t valid = 0;
      bool constant = true;
      for (std::uint32_t j = 0; j < table.n_bins(); ++j) {
        if (std::isnan(v[j])) continue;
        if (valid++ == 0) first = v[j];
        constant = constant && v[j] == first;
      }
      if (valid >= 2 && constant)
        throw FormatError(where + "has row " + std::to_string(r) + " constant (" + std::to_string(first) +
                          " mm in all " + std::to_string(valid) + " of its bins): not a measured curve");
    }
  }
}

std::vector<std::uint32_t> candidate_names_to_indices(const ExemplarTable& table,
                                                      const std::vector<std::string>& names) {
  std::vector<std::uint32_t> out;
  for (const auto& n : names) {
    std::vector<std::uint32_t> entries;
    if (n.find('@') != std::string::npos) {
      if (const auto i = table.index_of(n); i >= 0) entries.push_back(static_cast<std::uint32_t>(i));
    } else {
      for (std::uint32_t k = 0; k < table.n_materials(); ++k)
        if (table.material_of(k) == n) entries.push_back(k);
    }
    if (entries.empty()) throw std::invalid_argument("candidate \"" + n + "\" is not in the table");
    for (std::uint32_t k : entries) {
      if (std::find(out.begin(), out.end(), k) != out.end())
        throw std::invalid_argument("candidate \"" + n + "\" is given twice (as \"" + table.materials()[k] +
                                    "\" or its material)");
      out.push_back(k);
    }
  }
  return out;
}

std::vector<std::uint32_t> candidate_indices(std::size_t n_materials, std::vector<std::uint32_t> candidates) {
  if (candidates.empty()) {
    candidates.resize(n_materials);
    for (std::uint32_t i = 0; i < candidates.size(); ++i) candidates[i] = i;
  }
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  for (std::uint32_t c : candidates) {
    if (c >= n_materials) {
      throw std::invalid_argument("candidate index " + std::to_string(c) + " is outside the table's " +
                                  std::to_string(n_materials) + " materials");
    }
  }
  return candidates;
}

}  // namespace tofmat
