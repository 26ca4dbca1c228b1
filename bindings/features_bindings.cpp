// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// DepthBinAccumulator for Python: per-frame observations into a partial Eq. (10) query.
#include <pybind11/stl.h>

#include <cstring>

#include "bindings.hpp"
#include "tofmat/core/depth_bins.hpp"
#include "tofmat/core/features.hpp"

namespace tofmat::py {

void register_features(pyb::module_& m) {
  m.attr("SPEED_OF_LIGHT_MM_PER_NS") = kSpeedOfLightMmPerNs;
  m.def("depth_from_phase_mm", &depth_from_phase_mm, pyb::arg("phase_rad"), pyb::arg("freq_mhz"),
        "Eq. (1): c * phase / (4 pi f), phase wrapped into [0, 2 pi).");
  m.def("unambiguous_range_mm", &unambiguous_range_mm, pyb::arg("freq_mhz"));

  pyb::class_<DepthBinAccumulator>(m, "DepthBinAccumulator",
                                   "Accumulates per-frame feature rows into depth bins; query() is the partial "
                                   "feature vector for Eq. (12).")
      .def(pyb::init<BinSpec, std::uint32_t>(), pyb::arg("bins"), pyb::arg("n_rows"))
      .def(
          "add",
          [](DepthBinAccumulator& acc, double depth_mm, const pyb::handle& values) {
            auto v = as_float32(values, {static_cast<pyb::ssize_t>(acc.n_rows())}, "values");
            return acc.add(depth_mm, v.data());
          },
          pyb::arg("depth_mm"), pyb::arg("values"), "Add one observation; returns its bin or -1 if out of range.")
      .def(
          "add_many",
          [](DepthBinAccumulator& acc, const pyb::handle& depths, const pyb::handle& values) {
            auto v = as_float32(values, {-1, static_cast<pyb::ssize_t>(acc.n_rows())}, "values");
            auto d = pyb::array_t<double, pyb::array::c_style | pyb::array::forcecast>::ensure(depths);
            if (!d || d.ndim() != 1 || d.shape(0) != v.shape(0)) {
              throw pyb::value_error("depths must be a 1-D float array with one depth per row of values");
            }
            std::size_t added = 0;
            for (pyb::ssize_t i = 0; i < d.shape(0); ++i) {
              added += acc.add(d.data()[i], v.data() + i * acc.n_rows()) >= 0;
            }
            return added;
          },
          pyb::arg("depths_mm"), pyb::arg("values"), "Add many observations; returns how many fell in a bin.")
      .def(
          "add_sums",
          [](DepthBinAccumulator& acc, double depth_mm, const pyb::handle& sums, std::uint64_t count) {
            auto v = pyb::array_t<double, pyb::array::c_style | pyb::array::forcecast>::ensure(sums);
            if (!v || v.ndim() != 1 || v.shape(0) != static_cast<pyb::ssize_t>(acc.n_rows())) {
              throw pyb::value_error("sums must be a 1-D float array with one sum per row");
            }
            return acc.add_sums(depth_mm, v.data(), count);
          },
          pyb::arg("depth_mm"), pyb::arg("sums"), pyb::arg("count"),
          "Add `count` observations whose values sum to `sums` (a region's surface at its mean depth); returns "
          "the bin, or -1 if out of range or count is 0.")
      .def(
          "query",
          [](const DepthBinAccumulator& acc, std::uint64_t min_count) {
            const auto q = acc.query(min_count);
            pyb::array_t<float> out(
                {static_cast<pyb::ssize_t>(acc.n_rows()), static_cast<pyb::ssize_t>(acc.bins().count)});
            std::memcpy(out.mutable_data(), q.data(), q.size() * sizeof(float));
            return out;
          },
          pyb::arg("min_count") = 1, "Per-bin means (n_rows, n_bins), NaN where fewer than min_count observations.")
      .def("bins_covered", &DepthBinAccumulator::bins_covered, pyb::arg("min_count") = 1)
      .def("count", &DepthBinAccumulator::count, pyb::arg("row"), pyb::arg("bin"))
      .def("reset", &DepthBinAccumulator::reset)
      .def_property_readonly("bins", &DepthBinAccumulator::bins)
      .def_property_readonly("n_rows", &DepthBinAccumulator::n_rows);
}

}  // namespace tofmat::py
