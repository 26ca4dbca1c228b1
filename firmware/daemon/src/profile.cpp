// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Backend and classifier names, candidate lookup, profile configuration checks, and the factory of the scene profiles.
#include "tofmat/daemon/profile.hpp"

#include <stdexcept>

#include <spdlog/fmt/fmt.h>

#include "tofmat/core/features.hpp"

namespace tofmat::daemon {

std::unique_ptr<Profile> make_handheld(const ProfileConfig&, std::shared_ptr<const ExemplarTable>);
std::unique_ptr<Profile> make_segmentation(const ProfileConfig&, std::shared_ptr<const ExemplarTable>);
std::unique_ptr<Profile> make_sorting(const ProfileConfig&, const std::shared_ptr<const ExemplarTable>&);

Backend parse_backend(const std::string& name) {
  if (name == "fixed") return Backend::kFixed;
  if (name == "float") return Backend::kFloat;
  throw std::invalid_argument("unknown backend \"" + name + "\" (fixed, float)");
}

Method parse_method(const std::string& name) {
  if (name == "eq12") return Method::kEq12;
  if (name == "session") return Method::kSession;
  if (name.rfind("onnx:", 0) == 0 && name.size() > 5) return Method::kOnnx;
  throw std::invalid_argument("unknown classifier \"" + name + "\" (eq12, session, onnx:FILE)");
}

const char* method_name(Method method) {
  switch (method) {
    case Method::kSession: return "session";
    case Method::kOnnx: return "onnx";
    case Method::kEq12: break;
  }
  return "eq12";
}

std::uint64_t Profile::trigger(int) { throw std::logic_error("only the sorting profile takes triggers"); }

std::vector<std::uint32_t> candidate_indices(const ExemplarTable& table, const std::vector<std::string>& names) {
  return candidate_names_to_indices(table, names);
}

void validate(const ProfileConfig& c, const ExemplarTable& table) {
  if (c.name != "handheld" && c.name != "segmentation" && c.name != "sorting")
    throw std::invalid_argument("unknown profile \"" + c.name + "\" (handheld, segmentation, sorting)");
  const PixelRegion& r = c.roi;
  if (r.x0 < 0 || r.y0 < 0 || r.x1 > kWidth || r.y1 > kHeight || r.x0 >= r.x1 || r.y0 >= r.y1)
    throw std::invalid_argument("ROI [" + std::to_string(r.x0) + ", " + std::to_string(r.x1) + ") x [" +
                                std::to_string(r.y0) + ", " + std::to_string(r.y1) +
                                ") is empty or outside the 512 x 424 frame");
  candidate_indices(table, c.candidates);
  if (c.name == "segmentation" && c.candidates.size() > 254)
    throw std::invalid_argument("segmentation: at most 254 candidates (the label map is uint8)");
  if (c.top_k < 1 || c.top_k > 64) throw std::invalid_argument("top_k must lie in [1, 64]");
  if (c.burst < 1 || c.burst > 300) throw std::invalid_argument("burst must lie in [1, 300] frames");
  if (c.smooth < 1 || c.smooth > 15 || c.smooth % 2 == 0)
    throw std::invalid_argument("smooth must be an odd number of pixels in [1, 15]");
  if (c.accumulate < 1 || c.accumulate > 256) throw std::invalid_argument("accumulate must be 1..256 frames");
  if (c.threads < 0 || c.threads > 64) throw std::invalid_argument("threads must lie in [0, 64] (0: every core)");
  if (!(c.min_valid_fraction > 0.0 && c.min_valid_fraction <= 1.0))
    throw std::invalid_argument("min_valid_fraction must lie in (0, 1]");
  // The decode's features are the Kinect v2 rows: the table must be made of them.
  const auto& rows = table.rows();
  if (rows.size() != 2 || rows[0].freq_mhz != 16.0 || rows[0].ref_freq_mhz != 120.0 || rows[1].freq_mhz != 80.0 ||
      rows[1].ref_freq_mhz != 120.0)
    throw std::invalid_argument("the table's rows must be d(16 MHz) - d(120 MHz) and d(80 MHz) - d(120 MHz)");
}

std::unique_ptr<Profile> make_profile(const ProfileConfig& config, std::shared_ptr<const ExemplarTable> table) {
  validate(config, *table);
  if (config.name == "handheld") return make_handheld(config, std::move(table));
  if (config.name == "segmentation") return make_segmentation(config, std::move(table));
  return make_sorting(config, table);
}

TargetView view_target(std::size_t valid, std::size_t pixels, double median_mm, double min_valid_fraction,
                       const BinSpec& bins) {
  TargetView v;
  if (static_cast<double>(valid) < min_valid_fraction * static_cast<double>(pixels)) return v;  // none
  v.depth_mm = median_mm;
  if (median_mm >= bins.start_mm - 50.0 && median_mm <= bins.end_mm() + 50.0) {
    v.state = "in_range";
    return v;
  }
  v.state = "out_of_range";
  v.reason = fmt::format(
      "the target at {:.0f} mm lies outside the table's bins ({:.0f} to {:.0f} mm): no label until it moves into "
      "them, or a table recorded at its depth is loaded",
      median_mm, bins.start_mm, bins.end_mm());
  return v;
}

}  // namespace tofmat::daemon
