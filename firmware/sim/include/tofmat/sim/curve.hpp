// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A material's noise-free relative-distortion curve as the real database
// records it: a sweep of true range, decoded per frequency, binned by the
// combined depth (docs/simulator-model.md, section 4).
#pragma once

#include <vector>

#include "tofmat/core/bin_spec.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/sim/device.hpp"
#include "tofmat/sim/material.hpp"

namespace tofmat::sim {

enum class CurveMethod {
  kInterpolate,  // rows interpolated at bin centres (smooth in the parameters: fitting)
  kBinMean,      // samples averaged per bin with DepthBinAccumulator (as the database was built)
};

struct SweepSpec {
  double start_mm = 450.0;
  double stop_mm = 1400.0;
  double step_mm = 0.25;
};

// n_rows x n_bins (rows as `rows`, e.g. kinect2_database_rows()), NaN where no
// sample reached a bin. Throws std::invalid_argument on an unusable spec.
std::vector<float> distortion_curve(const DeviceProfile& device, const Material& material, const BinSpec& bins,
                                    const std::vector<RowSpec>& rows, double incidence_rad, CurveMethod method,
                                    const SweepSpec& sweep = {});

}  // namespace tofmat::sim
