// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The _tofmat extension module: registers every binding file's part, the logging sink first.
#include "bindings.hpp"

PYBIND11_MODULE(_tofmat, m) {
  m.doc() = "tofmat core (C++) bindings; use the tofmat package, not this module directly.";
  tofmat::py::register_logging(m);
  tofmat::py::register_errors(m);
  tofmat::py::register_table(m);
  tofmat::py::register_classifier(m);
  tofmat::py::register_features(m);
  tofmat::py::register_decode(m);
  tofmat::py::register_sim(m);
  tofmat::py::register_kinect(m);
  tofmat::py::register_client(m);
  tofmat::py::register_record(m);
}
