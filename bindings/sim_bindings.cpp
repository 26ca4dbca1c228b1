// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmat._tofmat.sim: the physically based Kinect v2 simulator (device profiles, material
// library, renderer) for the SDK's tofmat.sim.
#include <pybind11/complex.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cstring>

#include "bindings.hpp"
#include "tofmat/core/decode.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/daemon/sim_source.hpp"
#include "tofmat/sim/curve.hpp"
#include "tofmat/sim/profile_io.hpp"
#include "tofmat/sim/renderer.hpp"
#include "tofmat/sim/stage.hpp"

namespace tofmat::py {

namespace {

using namespace tofmat::sim;

// Dicts cross the boundary as JSON text: one schema, parsed and checked in C++.
pyb::object json_module() { return pyb::module_::import("json"); }
std::string dumps(const pyb::dict& d) { return pyb::cast<std::string>(json_module().attr("dumps")(d)); }
pyb::object loads(const std::string& s) { return json_module().attr("loads")(s); }

CurveMethod method_from(const std::string& name) {
  if (name == "interp") return CurveMethod::kInterpolate;
  if (name == "bin") return CurveMethod::kBinMean;
  throw pyb::value_error("method must be 'interp' or 'bin', got '" + name + "'");
}

template <typename T>
pyb::array_t<T> image(const std::vector<T>& v, std::vector<pyb::ssize_t> shape) {
  pyb::array_t<T> out(shape);
  std::memcpy(out.mutable_data(), v.data(), v.size() * sizeof(T));
  return out;
}

}  // namespace

void register_sim(pyb::module_& parent) {
  auto m = parent.def_submodule("sim", "Physically based Kinect v2 simulator (firmware/sim).");

  pyb::class_<Material>(m, "Material", "A material's temporal response parameters (closed forms).")
      .def_static(
          "from_dict", [](const pyb::dict& d) { return material_from_json(dumps(d)); }, pyb::arg("params"))
      .def("to_dict", [](const Material& x) { return loads(material_to_json(x)); })
      .def_readonly("name", &Material::name)
      .def_property_readonly("kind", [](const Material& x) { return std::string(response_kind_name(x.kind)); })
      .def(
          "response",
          [](const Material& x, double freq_hz, double incidence_deg) {
            return material_response(x, freq_hz, incidence_deg * kPi / 180.0);
          },
          pyb::arg("freq_hz"), pyb::arg("incidence_deg") = 0.0, "R(nu, alpha), the response's Fourier coefficient.")
      .def("__repr__",
           [](const Material& x) { return "<sim.Material " + x.name + " (" + response_kind_name(x.kind) + ")>"; });

  pyb::class_<DeviceProfile>(m, "DeviceProfile", "A ToF camera's parameters (harmonics, errors, noise, optics).")
      .def_static(
          "from_dict", [](const pyb::dict& d) { return device_from_json(dumps(d)); }, pyb::arg("params"))
      .def_static("ideal_kinect2", &DeviceProfile::ideal_kinect2)
      .def_static("load", &load_device, pyb::arg("name_or_path"), pyb::arg("data_dir"))
      .def("to_dict", [](const DeviceProfile& d) { return loads(device_to_json(d)); })
      .def("in_session", &DeviceProfile::in_session, pyb::arg("state"),
           "The device in one capture session: harmonics G_h + t_f dG_h, state = (t_80, t_16, t_120).")
      .def_readonly("name", &DeviceProfile::name)
      .def("__repr__", [](const DeviceProfile& d) { return "<sim.DeviceProfile " + d.name + ">"; });

  pyb::class_<MaterialLibrary>(m, "MaterialLibrary", "Named materials, loaded from a versioned JSON file.")
      .def_static(
          "from_dict", [](const pyb::dict& d) { return library_from_json(dumps(d)); }, pyb::arg("params"))
      .def_static("load", &load_library, pyb::arg("name_or_path"), pyb::arg("data_dir"))
      .def("to_dict", [](const MaterialLibrary& l) { return loads(library_to_json(l)); })
      .def_readonly("name", &MaterialLibrary::name)
      .def_readonly("materials", &MaterialLibrary::materials)
      .def_property_readonly("names",
                             [](const MaterialLibrary& l) {
                               std::vector<std::string> out;
                               for (const auto& x : l.materials) out.push_back(x.name);
                               return out;
                             })
      .def("__getitem__", &MaterialLibrary::find, pyb::arg("material"))
      .def("__len__", [](const MaterialLibrary& l) { return l.materials.size(); });

  m.def(
      "distortion_curves",
      [](const DeviceProfile& device, const std::vector<Material>& materials, const BinSpec& bins, double incidence_deg,
         const std::string& method) {
        const CurveMethod cm = method_from(method);
        const auto rows = kinect2_database_rows();
        std::vector<std::vector<float>> curves(materials.size());
        {
          pyb::gil_scoped_release nogil;
          for (std::size_t i = 0; i < materials.size(); ++i) {
            curves[i] = distortion_curve(device, materials[i], bins, rows, incidence_deg * kPi / 180.0, cm);
          }
        }
        pyb::array_t<float> out({static_cast<pyb::ssize_t>(materials.size()), static_cast<pyb::ssize_t>(rows.size()),
                                 static_cast<pyb::ssize_t>(bins.count)});
        for (std::size_t i = 0; i < curves.size(); ++i) {
          std::memcpy(out.mutable_data() + i * curves[i].size(), curves[i].data(), curves[i].size() * sizeof(float));
        }
        return out;
      },
      pyb::arg("device"), pyb::arg("materials"), pyb::arg("bins"), pyb::arg("incidence_deg") = 0.0,
      pyb::arg("method") = "interp",
      "Noise-free relative-distortion curves (n, 2, bins): rows d16-d120, d80-d120 vs combined depth.");

  pyb::class_<Target>(m, "Target", "A planar (optionally folded) target covering a pixel rectangle.")
      .def(pyb::init([](std::string material, double depth_mm, double yaw_deg, double pitch_deg, double fold_deg,
                        std::array<int, 4> rect) {
             Target t;
             t.material = std::move(material);
             t.depth_mm = depth_mm;
             t.yaw_deg = yaw_deg;
             t.pitch_deg = pitch_deg;
             t.fold_deg = fold_deg;
             t.x0 = rect[0];
             t.y0 = rect[1];
             t.x1 = rect[2];
             t.y1 = rect[3];
             return t;
           }),
           pyb::arg("material"), pyb::arg("depth_mm"), pyb::arg("yaw_deg") = 0.0, pyb::arg("pitch_deg") = 0.0,
           pyb::arg("fold_deg") = 0.0, pyb::arg("rect") = std::array<int, 4>{196, 152, 316, 272},
           "rect = (x0, y0, x1, y1), exclusive ends.")
      .def_readwrite("material", &Target::material)
      .def_readwrite("depth_mm", &Target::depth_mm)
      .def_readwrite("yaw_deg", &Target::yaw_deg)
      .def_readwrite("pitch_deg", &Target::pitch_deg)
      .def_readwrite("fold_deg", &Target::fold_deg);

  pyb::class_<Scene>(m, "Scene")
      .def(pyb::init([](std::vector<Target> targets, std::string background_material, double background_depth_mm) {
             Scene s;
             s.targets = std::move(targets);
             s.background_material = std::move(background_material);
             s.background_depth_mm = background_depth_mm;
             return s;
           }),
           pyb::arg("targets"), pyb::arg("background_material") = "", pyb::arg("background_depth_mm") = 3000.0)
      .def_readwrite("targets", &Scene::targets)
      .def_static("centred_target", &Scene::centred_target, pyb::arg("material"), pyb::arg("depth_mm"),
                  pyb::arg("yaw_deg") = 0.0, pyb::arg("size") = 120)
      .def_static(
          "of_source",
          [](const std::string& spec, std::uint64_t frame) {
            try {
              return tofmat::daemon::sim_scene_at(tofmat::daemon::parse_sim_spec(spec), frame);
            } catch (const std::invalid_argument& e) {
              throw pyb::value_error(e.what());
            }
          },
          pyb::arg("spec"), pyb::arg("frame") = 0,
          "The scene tofmatd's `--source sim:SPEC` shows at a frame (SPEC: the text after \"sim:\"), e.g. to "
          "render its ground truth.");

  pyb::class_<Frame>(m, "Frame", "A rendered raw frame (or region) and its ground truth (numpy arrays).")
      .def_readonly("x0", &Frame::x0)
      .def_readonly("y0", &Frame::y0)
      .def_property_readonly("raw",
                             [](const Frame& f) {
                               return image(f.raw, {9, f.height, f.width});
                             })
      .def_property_readonly("range_mm",
                             [](const Frame& f) {
                               return image(f.range_mm, {f.height, f.width});
                             })
      .def_property_readonly("depth_mm",
                             [](const Frame& f) {
                               return image(f.depth_mm, {f.height, f.width});
                             })
      .def_property_readonly("target",
                             [](const Frame& f) {
                               return image(f.target, {f.height, f.width});
                             })
      .def_property_readonly("incidence_deg", [](const Frame& f) {
        return image(f.incidence_deg, {f.height, f.width});
      });

  pyb::class_<Renderer>(m, "Renderer")
      .def(pyb::init<DeviceProfile, MaterialLibrary, int>(), pyb::arg("device"), pyb::arg("library"),
           pyb::arg("threads") = 0,
           "threads: workers per frame (0: one per hardware thread); frames do not depend on it.")
      .def(
          "render",
          [](const Renderer& r, const Scene& s, std::uint64_t seed, bool noise) {
            pyb::gil_scoped_release nogil;
            return r.render(s, seed, noise);
          },
          pyb::arg("scene"), pyb::arg("seed") = 0, pyb::arg("noise") = true)
      .def(
          "render_region",
          [](const Renderer& r, const Scene& s, std::uint64_t seed, bool noise, std::array<int, 4> rect) {
            pyb::gil_scoped_release nogil;
            return r.render_region(s, seed, noise, PixelRect{rect[0], rect[1], rect[2], rect[3]});
          },
          pyb::arg("scene"), pyb::arg("seed"), pyb::arg("noise"), pyb::arg("rect"), "rect = (x0, y0, x1, y1).")
      .def(
          "pixel_phase",
          [](const Renderer& r) {
            const auto& c = r.device().camera;
            pyb::array_t<float> out(std::vector<pyb::ssize_t>{3, c.height, c.width});
            for (int g = 0; g < 3; ++g) {
              const auto& p = r.pixel_phase(g);
              std::memcpy(out.mutable_data() + static_cast<std::size_t>(g) * p.size(), p.data(),
                          p.size() * sizeof(float));
            }
            return out;
          },
          "Per-pixel phase (3, H, W) of the raw samples (the pattern the P0 tables correct).")
      .def(
          "p0_tables",
          [](const Renderer& r) {
            const auto& c = r.device().camera;
            pyb::array_t<float> out(std::vector<pyb::ssize_t>{3, c.height, c.width});
            for (int g = 0; g < 3; ++g) {
              const auto p = r.p0_table(g);
              std::memcpy(out.mutable_data() + static_cast<std::size_t>(g) * p.size(), p.data(),
                          p.size() * sizeof(float));
            }
            return out;
          },
          "The P0 corrections (3, H, W) the simulated device reports: -(pixel_phase + decode_offset_rad). "
          "Decode with these.")
      .def_property_readonly("device", &Renderer::device)
      .def_property_readonly("library", &Renderer::library);

  m.def(
      "stage_sweep",
      [](const Renderer& r, const Target& target, std::array<int, 4> roi, const std::vector<double>& stage_mm,
         int frames, std::uint64_t seed, bool noise) {
        StageCapture c;
        {
          pyb::gil_scoped_release nogil;
          c = stage_sweep(r, target, PixelRect{roi[0], roi[1], roi[2], roi[3]}, stage_mm, frames, seed, noise);
        }
        pyb::dict out;
        const auto n = static_cast<pyb::ssize_t>(c.stage_mm.size());
        out["stage_mm"] = pyb::array_t<double>(n, c.stage_mm.data());
        pyb::array_t<double> depth(std::vector<pyb::ssize_t>{3, n});
        for (std::size_t g = 0; g < 3; ++g) {
          std::memcpy(depth.mutable_data() + g * c.stage_mm.size(), c.depth_mm[g].data(),
                      c.stage_mm.size() * sizeof(double));
        }
        out["depth_mm"] = depth;
        out["combined_mm"] = pyb::array_t<double>(n, c.combined_mm.data());
        out["samples"] = pyb::array_t<std::uint32_t>(n, c.samples.data());
        return out;
      },
      pyb::arg("renderer"), pyb::arg("target"), pyb::arg("roi"), pyb::arg("stage_mm"), pyb::arg("frames") = 1,
      pyb::arg("seed") = 0, pyb::arg("noise") = true,
      "A translation-stage capture: dict of stage_mm, depth_mm (3, n: 80/16/120 MHz, unwrapped ROI means), "
      "combined_mm, samples.");
}

}  // namespace tofmat::py
