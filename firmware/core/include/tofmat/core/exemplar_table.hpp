// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The exemplar table: for each material, a curve of relative distortions
// (n_rows frequency pairs x n_bins depth bins), NaN where it was not observed.
// This is the database the nearest-neighbour classifier of Eq. (12) searches.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tofmat/core/bin_spec.hpp"

namespace tofmat {

// The material an entry's name names: the part before '@' ("cork@30" is an
// exemplar of "cork"), or the whole name without one.
std::string exemplar_material(const std::string& name);

// At most 255 materials: the protocol's limit (a label map's uint8 index, 255
// = none), so that every table that loads can be served.
inline constexpr std::size_t kMaxMaterials = 255;
// A folder of .npy files is bounded in bytes (all files together, by their
// sizes) before any is read.
inline constexpr std::uintmax_t kMaxTableFolderBytes = 64u << 20;
inline constexpr std::uint32_t kMaxRows = 16;
inline constexpr std::size_t kMaxNameBytes = 64;

// What one row holds: d(freq) - d(ref_freq) in mm (the database's sign, i.e.
// Eq. (10) negated). 0/0 means "unknown".
struct RowSpec {
  std::uint16_t freq_mhz = 0;
  std::uint16_t ref_freq_mhz = 0;
  bool operator==(const RowSpec& o) const { return freq_mhz == o.freq_mhz && ref_freq_mhz == o.ref_freq_mhz; }
};

// The real database's binning (its README): numpy.linspace(600, 1200, n_bins)
// bin edges, the defaults wherever a folder of .npy curves is imported.
inline constexpr double kDatabaseBinStartMm = 600.0;
inline constexpr double kDatabaseBinStopMm = 1200.0;

// Each material's absolute distortion of the combined depth, Eq. (8)'s
// measured minus true depth (mm), sampled at the centres of `grid`'s bins of
// the measured (combined) depth: what corrects a labelled pixel's depth. The
// database's rows are relative (Eq. (10)), so this comes from elsewhere: a
// table recorded with the simulated camera, or the calibrated simulator's
// fitted response of each material (tofmat table distortion).
struct DepthDistortion {
  BinSpec grid;
  std::vector<float> mm;  // n_materials x grid.count, material-major; NaN = unknown
};
inline constexpr double kMaxDistortionMm = 10000.0;

// What a table was calibrated for, and with (format 1.3; `tofmat table
// calibrate`): the session matcher's prior (the spreads of the sessions its
// queries were drawn in and the tuned noise model) and each method's
// confidence calibration (temperatures and open-set thresholds by sweep
// length, confidence.hpp's Calibration). tofmatd and the SDK use these in
// place of the built-in tuned ones.
struct MethodCalibration {
  std::string method;                                                 // "eq12" or "session"
  std::vector<std::pair<double, double>> temperatures, unknown_fits;  // (bins, value) knots
};
struct TableCalibration {
  std::vector<double> offset_sd_mm;  // per row
  double drift1_sd_mm = 0.0, drift2_sd_mm = 0.0;
  double noise_scale = 0.0, floor_mm = 0.0, huber_k = 0.0;
  std::uint32_t iterations = 0;
  std::vector<MethodCalibration> methods;
  // Its method's calibration, or nullptr.
  const MethodCalibration* method(const std::string& name) const;
  // Throws std::invalid_argument naming what is wrong: offsets not one per
  // row, a spread or noise setting negative or not finite, huber_k <= 0,
  // iterations not 1..100, an unknown or repeated method, knots not as
  // Calibration::validate wants them (at most kMaxCalibrationKnots each).
  void validate(std::uint32_t n_rows) const;
};
inline constexpr std::size_t kMaxCalibrationKnots = 64;

class ExemplarTable {
 public:
  // values: n_materials x n_rows x n_bins, C order, NaN = missing, everything
  // else finite. noise_mm: empty, or each material's bin noise per row
  // (n_materials x n_rows, mm; NaN = not measured, else finite and > 0), the
  // session matcher's per-material noise (session_classifier.hpp). Throws
  // std::invalid_argument on any inconsistency.
  ExemplarTable(std::vector<std::string> materials, std::vector<RowSpec> rows, BinSpec bins, std::vector<float> values,
                double quant_step_mm = 0.0, std::vector<float> noise_mm = {});

  // A folder of <material>.npy files, each (n_rows, n_bins) float64 in mm,
  // all the same shape; a bin where every row is exactly 0.0 is missing (the
  // real database's convention, see its README). Materials sorted by name.
  // The files do not carry their binning: bins are BinSpec::linspace(
  // bin_start_mm, bin_stop_mm, n_bins), as the authors built them. Empty
  // `rows` means the Kinect v2 database rows when there are two rows, else
  // rows of unknown frequency.
  static ExemplarTable from_npy_dir(const std::filesystem::path& dir, double bin_start_mm, double bin_stop_mm,
                                    std::vector<RowSpec> rows = {});

  std::size_t n_materials() const { return materials_.size(); }
  std::uint32_t n_rows() const { return static_cast<std::uint32_t>(rows_.size()); }
  std::uint32_t n_bins() const { return bins_.count; }
  std::size_t elements_per_material() const { return static_cast<std::size_t>(n_rows()) * n_bins(); }

  // The table's entries by name. An entry named "MATERIAL@TAG" is one exemplar
  // of MATERIAL (a recording at one angle, say "cork@30"): a table may hold
  // several of a material, and labels, rankings, candidates and sorting rules
  // speak of the material (exemplar_material()).
  const std::vector<std::string>& materials() const { return materials_; }
  // The distinct materials of the entries, in the order each first appears
  // (materials() itself for a table of one entry per material).
  const std::vector<std::string>& distinct_materials() const { return distinct_; }
  // The material entry m is an exemplar of, as an index into
  // distinct_materials(), and by name.
  std::uint32_t material_id(std::size_t m) const { return material_ids_.at(m); }
  const std::string& material_of(std::size_t m) const { return distinct_[material_id(m)]; }
  // Whether some material has more than one entry.
  bool has_exemplars() const { return distinct_.size() != materials_.size(); }
  const std::vector<RowSpec>& rows() const { return rows_; }
  const BinSpec& bins() const { return bins_; }
  // Step of the int16 quantisation this table went through (0 = never quantised).
  double quant_step_mm() const { return quant_step_mm_; }

  const std::vector<float>& values() const { return values_; }
  // Each material's bin noise per row (n_materials x n_rows, mm, NaN = not
  // measured), or empty when the table carries none.
  const std::vector<float>& noise_mm() const { return noise_mm_; }
  bool has_noise() const { return !noise_mm_.empty(); }
  // This table with `noise_mm` (as the constructor's; empty drops it).
  ExemplarTable with_noise(std::vector<float> noise_mm) const;
  // The depth distortion, if the table carries one.
  const std::optional<DepthDistortion>& distortion() const { return distortion_; }
  // This table with `d` (nothing drops it). Throws std::invalid_argument
  // unless the grid is valid, d.mm holds n_materials x grid.count values and
  // each is NaN or finite and at most kMaxDistortionMm in size.
  ExemplarTable with_distortion(std::optional<DepthDistortion> d) const;
  // Material m's distortion at a measured depth, linear between the grid's
  // samples; NaN outside them, next to an unknown sample, or without a distortion.
  double distortion_mm(std::size_t m, double measured_mm) const;
  // The table's own calibration, if it carries one.
  const std::optional<TableCalibration>& calibration() const { return calibration_; }
  // This table with `c` (nothing drops it); throws as TableCalibration::validate.
  ExemplarTable with_calibration(std::optional<TableCalibration> c) const;
  const float* material_values(std::size_t m) const { return values_.data() + m * elements_per_material(); }
  std::size_t valid_count(std::size_t m) const;

  // Index of a material name, or -1.
  std::int64_t index_of(const std::string& name) const;

 private:
  std::vector<std::string> materials_;
  std::vector<RowSpec> rows_;
  BinSpec bins_;
  std::vector<float> values_;
  double quant_step_mm_;
  std::vector<float> noise_mm_;
  std::optional<DepthDistortion> distortion_;
  std::optional<TableCalibration> calibration_;
  std::vector<std::string> distinct_;        // distinct_materials()
  std::vector<std::uint32_t> material_ids_;  // per entry, into distinct_
};

// The Kinect v2 database's rows: 16 vs 120 MHz, then 80 vs 120 MHz.
std::vector<RowSpec> kinect2_database_rows();

// Throws std::invalid_argument unless the name is 1..64 bytes of printable
// ASCII without spaces, not "unknown", and with at most one '@', between a
// material and a tag that are both non-empty (and the material not "unknown").
void validate_material_name(const std::string& name);

// Every material holds a measured curve: at least one valid value, and (with
// `rows_must_vary`, for curves read from files) no row whose valid values,
// two or more, are all one number (a fill value, a placeholder). One check
// for `tofmat table import` and ExemplarTable::from_npy_dir, tofmatd's table
// loads and the SDK's Classifier (which takes tables built in memory, whose
// rows may be constant on purpose: rows_must_vary false), so none of them
// serves a material the others refuse. Throws FormatError naming `source`
// (or, when given, the material's own file in `material_files`) and the
// material.
void check_measured(const ExemplarTable& table, const std::string& source,
                    const std::vector<std::string>& material_files = {}, bool rows_must_vary = true);

// Candidate names as indices into `table`, in the order given: a name with an
// '@' is one entry's ("cork@30": that exemplar), one without is a material's
// ("cork": each of its entries, "cork" and "cork@30" alike, in table order). Throws std::invalid_argument naming a name
// that is not in the table or that names an entry already given.
std::vector<std::uint32_t> candidate_names_to_indices(const ExemplarTable& table,
                                                      const std::vector<std::string>& names);

// A classifier's candidates: indices into a table of n_materials (empty:
// all), sorted and without repeats. Throws std::invalid_argument on an
// index outside the table.
std::vector<std::uint32_t> candidate_indices(std::size_t n_materials, std::vector<std::uint32_t> candidates);

}  // namespace tofmat
