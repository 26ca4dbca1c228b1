// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The paper's depth-distortion features (Tanaka et al., CVPR 2017, Sec. 4).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "tofmat/core/exemplar_table.hpp"

namespace tofmat {

// c in mm/ns as in the authors' code, the convention the real database was
// computed with. (The physical 299.792 mm/ns differs by 0.07 %, a scale common
// to every row that the classifier never sees as long as one constant is used.)
inline constexpr double kSpeedOfLightMmPerNs = 300.0;

// Kinect v2 modulation frequencies in raw sub-image order (0-2, 3-5, 6-8).
inline constexpr double kKinect2FrequenciesMhz[3] = {80.0, 16.0, 120.0};

// Eq. (1): depth from the phase of one frequency, d = c * phase / (4 pi f),
// with the phase first wrapped into [0, 2 pi). Non-finite phase gives NaN.
double depth_from_phase_mm(double phase_rad, double freq_mhz);

// Half the wavelength: the unambiguous range of one frequency, c / (2 f).
double unambiguous_range_mm(double freq_mhz);

// Eq. (8): absolute distortion v = d_true - d(f_i) (needs ground-truth depth).
inline double absolute_distortion_mm(double true_depth_mm, double measured_mm) { return true_depth_mm - measured_mm; }

// Eq. (10) as the paper writes it: v' = d(f_ref) - d(f_i).
inline double relative_distortion_mm(double d_ref_mm, double d_i_mm) { return d_ref_mm - d_i_mm; }

// Eq. (11): relative distortion across positions with one frequency,
// v'' = d(f, m) - d(f, j) + delta_j, where delta_j is the known movement of
// position j from the base position m.
inline double depth_relative_distortion_mm(double d_base_mm, double d_j_mm, double delta_j_mm) {
  return d_base_mm - d_j_mm + delta_j_mm;
}

// The table rows for one observation: out[r] = d(rows[r].freq) - d(rows[r].ref),
// i.e. Eq. (10) negated, the real database's sign. `freqs_mhz`/`depths_mm`
// give the per-frequency depths observed; a row whose frequency or reference
// is absent or whose depth is NaN gives NaN. Throws std::invalid_argument if a
// row has an unknown (0) frequency.
void frequency_features(const std::vector<RowSpec>& rows, const double* freqs_mhz, const double* depths_mm,
                        std::size_t n_freqs, float* out);

}  // namespace tofmat
