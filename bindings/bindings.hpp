// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Registration functions of the _tofmat module, one per binding file, and the
// numpy-argument checks they share.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>
#include <vector>

namespace tofmat::py {

namespace pyb = pybind11;
using FloatArray = pyb::array_t<float, pyb::array::c_style | pyb::array::forcecast>;

void register_errors(pyb::module_& m);
void register_table(pyb::module_& m);
void register_classifier(pyb::module_& m);
void register_features(pyb::module_& m);
void register_decode(pyb::module_& m);
void register_sim(pyb::module_& m);
void register_kinect(pyb::module_& m);
void register_client(pyb::module_& m);
void register_record(pyb::module_& m);
void register_logging(pyb::module_& m);

// A C-contiguous float32 copy/view of `a` after checking that it is a
// floating-point array of exactly `shape` (-1 = any size on that axis).
// Raises ValueError naming `what`, the expected and the actual shape/dtype.
FloatArray as_float32(const pyb::handle& a, const std::vector<pyb::ssize_t>& shape, const char* what);

}  // namespace tofmat::py
