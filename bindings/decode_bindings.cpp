// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The decode of raw Kinect v2 samples to per-frequency depth and Eq. (10) features (float and
// fixed point) for numpy arrays, with the GIL released.
#include <pybind11/stl.h>

#include <cstring>

#include "bindings.hpp"
#include "tofmat/core/depth_bins.hpp"
#include "tofmat/core/fixed_depth_bins.hpp"
#include "tofmat/core/frame_decode.hpp"

namespace tofmat::py {

namespace {
pyb::array_t<float> stack3(const std::array<std::vector<float>, 3>& planes, std::size_t pixels) {
  pyb::array_t<float> out(std::vector<pyb::ssize_t>{3, static_cast<pyb::ssize_t>(pixels)});
  for (std::size_t g = 0; g < 3; ++g)
    std::memcpy(out.mutable_data() + g * pixels, planes[g].data(), pixels * sizeof(float));
  return out;
}

DecodeOptions options_of(double min_amplitude, double min_mean_amplitude, double min_unwrap_amplitude,
                         double max_gap_16_80_mm, double max_gap_80_120_mm) {
  DecodeOptions opt;
  opt.min_amplitude = min_amplitude;
  opt.min_mean_amplitude = min_mean_amplitude;
  opt.min_unwrap_amplitude = min_unwrap_amplitude;
  opt.max_gap_16_80_mm = max_gap_16_80_mm;
  opt.max_gap_80_120_mm = max_gap_80_120_mm;
  return opt;
}
}  // namespace

void register_decode(pyb::module_& m) {
  pyb::class_<DecodedFrame>(m, "DecodedFrame", "Per-frequency phase/amplitude/depth and combined depth (numpy).")
      .def_readonly("pixels", &DecodedFrame::pixels)
      .def_property_readonly("phase_rad", [](const DecodedFrame& d) { return stack3(d.phase_rad, d.pixels); })
      .def_property_readonly("amplitude", [](const DecodedFrame& d) { return stack3(d.amplitude, d.pixels); })
      .def_property_readonly("depth_mm", [](const DecodedFrame& d) { return stack3(d.depth_mm, d.pixels); })
      .def_property_readonly("combined_mm",
                             [](const DecodedFrame& d) {
                               pyb::array_t<float> out(static_cast<pyb::ssize_t>(d.pixels));
                               std::memcpy(out.mutable_data(), d.combined_mm.data(), d.pixels * sizeof(float));
                               return out;
                             })
      .def_property_readonly(
          "features",
          [](const DecodedFrame& d) {
            pyb::array_t<float> out(std::vector<pyb::ssize_t>{2, static_cast<pyb::ssize_t>(d.pixels)});
            for (std::size_t r = 0; r < 2; ++r) {
              std::memcpy(out.mutable_data() + r * d.pixels, d.features[r].data(), d.pixels * sizeof(float));
            }
            return out;
          })
      .def_property_readonly("flags", [](const DecodedFrame& d) {
        pyb::array_t<std::uint8_t> out(static_cast<pyb::ssize_t>(d.pixels));
        std::memcpy(out.mutable_data(), d.flags.data(), d.pixels);
        return out;
      });
  pyb::class_<DecodeTables>(m, "DecodeTables",
                            "e^{-i p0} per pixel and group, built once from the P0 corrections (3, pixels).")
      .def(pyb::init([](const pyb::handle& p0_obj) {
             auto a = as_float32(p0_obj, {3, -1}, "p0_rad");
             std::vector<float> p0(a.data(), a.data() + a.size());
             return DecodeTables(p0, static_cast<std::size_t>(a.shape(1)));
           }),
           pyb::arg("p0_rad"))
      .def_readonly("pixels", &DecodeTables::pixels);
  m.attr("SURFACE_BAND_MM") = kSurfaceBandMm;
  m.def(
      "surface_mean",
      [](const DecodedFrame& f, double centre_mm, double band_mm) {
        const SurfaceMean s = surface_mean(f, centre_mm, band_mm);
        pyb::array_t<double> sums(2);
        sums.mutable_data()[0] = s.sum_mm[0];
        sums.mutable_data()[1] = s.sum_mm[1];
        return pyb::make_tuple(s.depth_mm, sums, s.pixels);
      },
      pyb::arg("frame"), pyb::arg("centre_mm"), pyb::arg("band_mm") = static_cast<double>(kSurfaceBandMm),
      "A region's surface as tofmatd bins it: (mean combined depth, the two features' sums, pixels) of the "
      "valid pixels within band_mm of centre_mm on the centre's side of every wrap (NaN depth, 0 pixels: none).");
  m.attr("DECODE_SATURATED") = kDecodeSaturated;
  m.attr("DECODE_DARK") = kDecodeDark;
  m.attr("DECODE_UNWRAP") = kDecodeUnwrap;
  const DecodeOptions defaults;

  m.def(
      "decode_frame",
      [](const pyb::handle& raw_obj, const pyb::object& p0_obj, double min_amplitude, double min_mean_amplitude,
         double min_unwrap_amplitude, double max_gap_16_80_mm, double max_gap_80_120_mm) {
        auto raw = pyb::array_t<std::int16_t, pyb::array::c_style>::ensure(raw_obj);
        if (!raw || raw.ndim() < 2 || raw.shape(0) != 9) {
          throw pyb::value_error("raw must be an int16 array of shape (9, ...) (the nine phase-step images)");
        }
        const auto pixels = static_cast<std::size_t>(raw.size() / 9);
        const DecodeOptions opt =
            options_of(min_amplitude, min_mean_amplitude, min_unwrap_amplitude, max_gap_16_80_mm, max_gap_80_120_mm);
        if (pyb::isinstance<DecodeTables>(p0_obj)) {  // prepared once: no per-call P0 work
          const auto& t = p0_obj.cast<const DecodeTables&>();
          if (t.pixels != pixels) throw pyb::value_error("the decode tables are for another pixel count");
          pyb::gil_scoped_release nogil;
          return decode_frame(raw.data(), t, opt);
        }
        std::vector<float> p0;
        if (!p0_obj.is_none()) {
          auto a = as_float32(p0_obj, {3, -1}, "p0_rad");
          if (static_cast<std::size_t>(a.shape(1)) != pixels) throw pyb::value_error("p0_rad must be (3, pixels)");
          p0.assign(a.data(), a.data() + a.size());
        }
        pyb::gil_scoped_release nogil;
        return decode_frame(raw.data(), pixels, p0, opt);
      },
      pyb::arg("raw"), pyb::arg("p0_rad") = pyb::none(), pyb::arg("min_amplitude") = defaults.min_amplitude,
      pyb::arg("min_mean_amplitude") = defaults.min_mean_amplitude,
      pyb::arg("min_unwrap_amplitude") = defaults.min_unwrap_amplitude,
      pyb::arg("max_gap_16_80_mm") = defaults.max_gap_16_80_mm,
      pyb::arg("max_gap_80_120_mm") = defaults.max_gap_80_120_mm,
      "Decode raw (9, ...) int16 samples; p0_rad: (3, pixels) per-pixel corrections, or DecodeTables built from "
      "them once. Outputs are flat per pixel. Flags: DECODE_SATURATED, DECODE_DARK (a group below min_amplitude or "
      "the mean below min_mean_amplitude), DECODE_UNWRAP (16 MHz below min_unwrap_amplitude, or the unwrapped "
      "depths more than max_gap_16_80_mm / max_gap_80_120_mm apart).");

  m.def(
      "decode_region",
      [](const pyb::handle& raw_obj, const pyb::object& p0_obj, std::array<int, 4> rect, double min_amplitude,
         double min_mean_amplitude, double min_unwrap_amplitude, double max_gap_16_80_mm, double max_gap_80_120_mm) {
        auto raw = pyb::array_t<std::int16_t, pyb::array::c_style>::ensure(raw_obj);
        if (!raw || raw.ndim() != 3 || raw.shape(0) != 9) {
          throw pyb::value_error("raw must be an int16 array of shape (9, height, width)");
        }
        const int h = static_cast<int>(raw.shape(1)), w = static_cast<int>(raw.shape(2));
        const auto pixels = static_cast<std::size_t>(h) * static_cast<std::size_t>(w);
        const PixelRegion region{rect[0], rect[1], rect[2], rect[3]};
        const DecodeOptions opt =
            options_of(min_amplitude, min_mean_amplitude, min_unwrap_amplitude, max_gap_16_80_mm, max_gap_80_120_mm);
        if (pyb::isinstance<DecodeTables>(p0_obj)) {
          const auto& t = p0_obj.cast<const DecodeTables&>();
          pyb::gil_scoped_release nogil;
          return decode_region(raw.data(), w, h, t, region, opt);
        }
        std::vector<float> p0;
        if (!p0_obj.is_none()) {
          auto a = as_float32(p0_obj, {3, -1}, "p0_rad");
          if (static_cast<std::size_t>(a.shape(1)) != pixels)
            throw pyb::value_error("p0_rad must be (3, height * width)");
          p0.assign(a.data(), a.data() + a.size());
        }
        pyb::gil_scoped_release nogil;
        return decode_region(raw.data(), w, h, p0, region, opt);
      },
      pyb::arg("raw"), pyb::arg("p0_rad"), pyb::arg("rect"), pyb::arg("min_amplitude") = defaults.min_amplitude,
      pyb::arg("min_mean_amplitude") = defaults.min_mean_amplitude,
      pyb::arg("min_unwrap_amplitude") = defaults.min_unwrap_amplitude,
      pyb::arg("max_gap_16_80_mm") = defaults.max_gap_16_80_mm,
      pyb::arg("max_gap_80_120_mm") = defaults.max_gap_80_120_mm,
      "Decode only the pixels of rect = (x0, y0, x1, y1) of a (9, height, width) frame; outputs flat, row by row.");
}

}  // namespace tofmat::py
