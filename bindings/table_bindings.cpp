// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// BinSpec and ExemplarTable for Python: the real database's .npy folders, the compact .tmx file,
// and the features as numpy arrays.
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <optional>

#include "bindings.hpp"
#include "tofmat/core/bin_spec.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/npy.hpp"
#include "tofmat/core/table_file.hpp"

namespace tofmat::py {

namespace {

using Table = std::shared_ptr<ExemplarTable>;  // pybind11 holders cannot be const; nothing mutates a table

using Knots = std::vector<std::pair<double, double>>;

// (bins, value) knots as [[bins, value], ...]: what JSON gives back.
pyb::list knot_list(const Knots& knots) {
  pyb::list out;
  for (const auto& [bins, v] : knots) {
    pyb::list knot;
    knot.append(bins);
    knot.append(v);
    out.append(knot);
  }
  return out;
}

// A table's calibration as Python sees it: a dict of plain numbers and lists.
pyb::dict calibration_dict(const TableCalibration& c) {
  pyb::dict methods;
  for (const MethodCalibration& m : c.methods) {
    pyb::dict d;
    d["temperatures"] = knot_list(m.temperatures);
    d["unknown_fits"] = knot_list(m.unknown_fits);
    methods[pyb::str(m.method)] = d;
  }
  pyb::dict out;
  out["offset_sd_mm"] = c.offset_sd_mm;
  out["drift_sd_mm"] = std::vector<double>{c.drift1_sd_mm, c.drift2_sd_mm};
  out["noise_scale"] = c.noise_scale;
  out["floor_mm"] = c.floor_mm;
  out["huber_k"] = c.huber_k;
  out["iterations"] = c.iterations;
  out["methods"] = methods;
  return out;
}

TableCalibration calibration_of(const pyb::dict& d) {
  static const char* const keys[] = {"offset_sd_mm", "drift_sd_mm", "noise_scale", "floor_mm",
                                     "huber_k",      "iterations",  "methods"};
  for (const auto& [k, v] : d) {
    const auto key = pyb::cast<std::string>(k);
    if (std::find_if(std::begin(keys), std::end(keys), [&](const char* x) { return key == x; }) == std::end(keys))
      throw pyb::value_error("calibration: unknown key '" + key + "'");
  }
  for (const char* k : keys)
    if (!d.contains(k)) throw pyb::value_error(std::string("calibration: '") + k + "' is missing");
  TableCalibration c;
  c.offset_sd_mm = pyb::cast<std::vector<double>>(d["offset_sd_mm"]);
  const auto drift = pyb::cast<std::vector<double>>(d["drift_sd_mm"]);
  if (drift.size() != 2) throw pyb::value_error("calibration: 'drift_sd_mm' holds the two drift terms' sds");
  c.drift1_sd_mm = drift[0];
  c.drift2_sd_mm = drift[1];
  c.noise_scale = pyb::cast<double>(d["noise_scale"]);
  c.floor_mm = pyb::cast<double>(d["floor_mm"]);
  c.huber_k = pyb::cast<double>(d["huber_k"]);
  c.iterations = pyb::cast<std::uint32_t>(d["iterations"]);
  for (const auto& [name, m] : pyb::cast<pyb::dict>(d["methods"])) {
    const auto md = pyb::cast<pyb::dict>(m);
    MethodCalibration mc;
    mc.method = pyb::cast<std::string>(name);
    mc.temperatures = pyb::cast<Knots>(md["temperatures"]);
    mc.unknown_fits = md.contains("unknown_fits") ? pyb::cast<Knots>(md["unknown_fits"]) : Knots{};
    c.methods.push_back(std::move(mc));
  }
  return c;
}

pyb::array_t<double> bin_edges(const BinSpec& b) {
  pyb::array_t<double> out(b.count + 1);
  auto v = out.mutable_unchecked<1>();
  for (std::uint32_t j = 0; j <= b.count; ++j) v(j) = b.lower_edge_mm(j);
  return out;
}

pyb::array_t<double> bin_centres(const BinSpec& b) {
  pyb::array_t<double> out(b.count);
  auto v = out.mutable_unchecked<1>();
  for (std::uint32_t j = 0; j < b.count; ++j) v(j) = b.centre_mm(j);
  return out;
}

// A (n_materials, n_rows) noise array, or None: no noise.
std::vector<float> noise_from(const pyb::handle& noise, std::size_t n_materials, std::size_t n_rows) {
  if (noise.is_none()) return {};
  auto a = as_float32(noise, {static_cast<pyb::ssize_t>(n_materials), static_cast<pyb::ssize_t>(n_rows)}, "noise_mm");
  return std::vector<float>(a.data(), a.data() + a.size());
}

std::vector<RowSpec> rows_from(const std::vector<std::pair<int, int>>& rows) {
  std::vector<RowSpec> out;
  for (const auto& [f, ref] : rows) {
    if (f < 0 || f > 65535 || ref < 0 || ref > 65535) throw pyb::value_error("row frequencies must be 0..65535 MHz");
    out.push_back(RowSpec{static_cast<std::uint16_t>(f), static_cast<std::uint16_t>(ref)});
  }
  return out;
}

}  // namespace

void register_table(pyb::module_& m) {
  pyb::class_<BinSpec>(m, "BinSpec", "Depth bins: `count` bins of `width_mm` starting at `start_mm`.")
      .def(pyb::init([](double start, double width, std::uint32_t count) {
             BinSpec b{start, width, count};
             b.validate();
             return b;
           }),
           pyb::arg("start_mm"), pyb::arg("width_mm"), pyb::arg("count"))
      .def_static("linspace", &BinSpec::linspace, pyb::arg("start_mm"), pyb::arg("stop_mm"), pyb::arg("count"),
                  "Bins whose left edges are numpy.linspace(start_mm, stop_mm, count).")
      .def_readonly("start_mm", &BinSpec::start_mm)
      .def_readonly("width_mm", &BinSpec::width_mm)
      .def_readonly("count", &BinSpec::count)
      .def("index_of", &BinSpec::index_of, pyb::arg("depth_mm"), "Bin index of a depth, -1 outside.")
      .def_property_readonly("edges_mm", &bin_edges)
      .def_property_readonly("centres_mm", &bin_centres)
      .def("__eq__", &BinSpec::operator==)
      .def("__repr__", [](const BinSpec& b) {
        return "BinSpec(start_mm=" + std::to_string(b.start_mm) + ", width_mm=" + std::to_string(b.width_mm) +
               ", count=" + std::to_string(b.count) + ")";
      });

  pyb::class_<ExemplarTable, Table>(m, "ExemplarTable",
                                    "Per-material relative-distortion curves (materials x rows x bins), NaN missing.")
      .def(pyb::init([](std::vector<std::string> materials, const pyb::handle& features, BinSpec bins,
                        std::vector<std::pair<int, int>> rows, const pyb::handle& noise_mm) {
             const auto n_m = static_cast<pyb::ssize_t>(materials.size());
             const auto n_r = static_cast<pyb::ssize_t>(rows.size());
             auto a = as_float32(features, {n_m, n_r, static_cast<pyb::ssize_t>(bins.count)}, "features");
             std::vector<float> values(a.data(), a.data() + a.size());
             auto noise = noise_from(noise_mm, materials.size(), rows.size());
             return std::make_shared<ExemplarTable>(std::move(materials), rows_from(rows), bins, std::move(values), 0.0,
                                                    std::move(noise));
           }),
           pyb::arg("materials"), pyb::arg("features"), pyb::arg("bins"), pyb::arg("rows"),
           pyb::arg("noise_mm") = pyb::none(),
           "features: float array (len(materials), len(rows), bins.count), NaN = missing. "
           "rows: (freq_mhz, ref_freq_mhz) per row; a row holds d(freq) - d(ref). "
           "noise_mm: None, or each material's bin noise per row (len(materials), len(rows)), mm, "
           "NaN = not measured, else > 0; the session matcher's per-material noise.")
      .def_static(
          "from_npy_dir",
          [](const std::filesystem::path& dir, double start, double stop) {
            return std::make_shared<ExemplarTable>(ExemplarTable::from_npy_dir(dir, start, stop));
          },
          pyb::arg("path"), pyb::arg("bin_start_mm") = kDatabaseBinStartMm,
          pyb::arg("bin_stop_mm") = kDatabaseBinStopMm,
          "Import a folder of <material>.npy curves (the real database's layout). Bins are "
          "numpy.linspace(bin_start_mm, bin_stop_mm, n_bins), as the authors built them.")
      .def_static(
          "load", [](const std::filesystem::path& p) { return std::make_shared<ExemplarTable>(load_table(p)); },
          pyb::arg("path"), "Load a compact table file (.tmx).")
      .def(
          "save", [](const ExemplarTable& t, const std::filesystem::path& p) { save_table(t, p); }, pyb::arg("path"),
          "Save as a compact table file (.tmx), atomically.")
      .def_property_readonly("materials", &ExemplarTable::materials)
      .def_property_readonly("bins", &ExemplarTable::bins)
      .def_property_readonly("bin_edges_mm", [](const ExemplarTable& t) { return bin_edges(t.bins()); })
      .def_property_readonly("bin_centres_mm", [](const ExemplarTable& t) { return bin_centres(t.bins()); })
      .def_property_readonly("rows",
                             [](const ExemplarTable& t) {
                               std::vector<std::pair<int, int>> out;
                               for (const auto& r : t.rows()) out.emplace_back(r.freq_mhz, r.ref_freq_mhz);
                               return out;
                             })
      .def_property_readonly("n_rows", &ExemplarTable::n_rows)
      .def_property_readonly("n_bins", &ExemplarTable::n_bins)
      .def_property_readonly("quant_step_mm", &ExemplarTable::quant_step_mm,
                             "Step of the int16 quantisation the values went through (0: never quantised).")
      .def_property_readonly(
          "noise_mm",
          [](const ExemplarTable& t) -> std::optional<pyb::array_t<double>> {
            if (!t.has_noise()) return std::nullopt;
            pyb::array_t<double> out(
                {static_cast<pyb::ssize_t>(t.n_materials()), static_cast<pyb::ssize_t>(t.n_rows())});
            std::copy(t.noise_mm().begin(), t.noise_mm().end(), out.mutable_data());
            return out;
          },
          "Each material's bin noise per row (n_materials, n_rows), mm, NaN = not measured; None when the "
          "table carries none (a version 1.0 file).")
      .def(
          "with_noise",
          [](const ExemplarTable& t, const pyb::handle& noise_mm) {
            return std::make_shared<ExemplarTable>(t.with_noise(noise_from(noise_mm, t.n_materials(), t.n_rows())));
          },
          pyb::arg("noise_mm"), "A copy of this table carrying noise_mm (as the constructor's; None drops it).")
      .def_property_readonly(
          "distortion_grid",
          [](const ExemplarTable& t) -> std::optional<BinSpec> {
            if (!t.distortion()) return std::nullopt;
            return t.distortion()->grid;
          },
          "The measured depths the depth distortion is sampled at (the centres of these bins), or None.")
      .def_property_readonly(
          "distortion_mm",
          [](const ExemplarTable& t) -> std::optional<pyb::array_t<double>> {
            if (!t.distortion()) return std::nullopt;
            const auto& d = *t.distortion();
            pyb::array_t<double> out(
                {static_cast<pyb::ssize_t>(t.n_materials()), static_cast<pyb::ssize_t>(d.grid.count)});
            std::copy(d.mm.begin(), d.mm.end(), out.mutable_data());
            return out;
          },
          "Each material's absolute distortion of the combined depth, Eq. (8)'s measured minus true depth "
          "(n_materials, grid count), mm, at distortion_grid's bin centres of the measured depth; NaN = unknown; "
          "None when the table carries none (files before version 1.2).")
      .def(
          "with_distortion",
          [](const ExemplarTable& t, const std::optional<BinSpec>& grid, const pyb::handle& distortion_mm) {
            if (!grid || distortion_mm.is_none()) {
              if (grid || !distortion_mm.is_none())
                throw pyb::value_error("give both grid and distortion_mm, or neither (None drops the distortion)");
              return std::make_shared<ExemplarTable>(t.with_distortion(std::nullopt));
            }
            auto a = as_float32(distortion_mm,
                                {static_cast<pyb::ssize_t>(t.n_materials()), static_cast<pyb::ssize_t>(grid->count)},
                                "distortion_mm");
            DepthDistortion d{*grid, std::vector<float>(a.data(), a.data() + a.size())};
            return std::make_shared<ExemplarTable>(t.with_distortion(std::move(d)));
          },
          pyb::arg("grid"), pyb::arg("distortion_mm"),
          "A copy of this table carrying a depth distortion: distortion_mm (n_materials, grid.count), mm, sampled "
          "at grid's bin centres of the measured depth, NaN = unknown (None, None drops it).")
      .def_property_readonly(
          "calibration",
          [](const ExemplarTable& t) -> std::optional<pyb::dict> {
            if (!t.calibration()) return std::nullopt;
            return calibration_dict(*t.calibration());
          },
          "The table's own calibration (format 1.3, tofmat table calibrate), or None: a dict of the session "
          "prior ('offset_sd_mm' per row, 'drift_sd_mm' (2), 'noise_scale', 'floor_mm', 'huber_k', 'iterations') "
          "and 'methods': {'eq12' | 'session': {'temperatures': [[bins, T], ...], 'unknown_fits': [[bins, fit], "
          "...]}}.")
      .def(
          "with_calibration",
          [](const ExemplarTable& t, const std::optional<pyb::dict>& c) {
            if (!c) return std::make_shared<ExemplarTable>(t.with_calibration(std::nullopt));
            return std::make_shared<ExemplarTable>(t.with_calibration(calibration_of(*c)));
          },
          pyb::arg("calibration"),
          "A copy of this table carrying a calibration (a dict as `calibration` gives; None drops it). Raises "
          "ValueError naming what is wrong.")
      .def(
          "distortion_at",
          [](const ExemplarTable& t, const std::string& material,
             const pyb::array_t<double, pyb::array::forcecast>& measured) {
            const std::int64_t index = t.index_of(material);
            if (index < 0) throw pyb::key_error("no material '" + material + "' in the table");
            pyb::array_t<double> out(measured.request().shape);
            const auto n = static_cast<std::size_t>(measured.size());
            const double* in = measured.data();
            double* o = out.mutable_data();
            for (std::size_t i = 0; i < n; ++i) o[i] = t.distortion_mm(static_cast<std::size_t>(index), in[i]);
            return out;
          },
          pyb::arg("material"), pyb::arg("measured_mm"),
          "The material's distortion at each measured depth (linear between samples; NaN outside them, next to "
          "an unknown one, or when the table has none): what tofmatd subtracts for the corrected depth.")
      .def_property_readonly(
          "features",
          [](const ExemplarTable& t) {
            pyb::array_t<float> out({static_cast<pyb::ssize_t>(t.n_materials()), static_cast<pyb::ssize_t>(t.n_rows()),
                                     static_cast<pyb::ssize_t>(t.n_bins())});
            std::memcpy(out.mutable_data(), t.values().data(), t.values().size() * sizeof(float));
            return out;
          })
      .def_property_readonly("valid_counts",
                             [](const ExemplarTable& t) {
                               std::vector<std::size_t> out;
                               for (std::size_t i = 0; i < t.n_materials(); ++i) out.push_back(t.valid_count(i));
                               return out;
                             })
      .def(
          "index_of",
          [](const ExemplarTable& t, const std::string& material) {
            const auto i = t.index_of(material);
            if (i < 0) {
              std::string names;
              for (const auto& name : t.materials()) names += (names.empty() ? "" : ", ") + name;
              throw pyb::key_error("unknown material '" + material + "'; the table has: " + names);
            }
            return i;
          },
          pyb::arg("material"), "Index of a material in `materials`. Raises KeyError for a name the table lacks.")
      .def("__len__", &ExemplarTable::n_materials)
      .def("__repr__", [](const ExemplarTable& t) {
        return "<ExemplarTable " + std::to_string(t.n_materials()) + " materials x " + std::to_string(t.n_rows()) +
               " rows x " + std::to_string(t.n_bins()) + " bins>";
      });

  m.def(
      "read_npy",
      [](const std::filesystem::path& p) {
        NpyArray a = read_npy_file(p);
        std::vector<pyb::ssize_t> shape(a.shape.begin(), a.shape.end());
        pyb::array_t<double> out(shape);
        std::memcpy(out.mutable_data(), a.data.data(), a.data.size() * sizeof(double));
        return out;
      },
      pyb::arg("path"), "Read a float .npy file with the core's bounded reader (Python 2 headers accepted).");
}

}  // namespace tofmat::py
