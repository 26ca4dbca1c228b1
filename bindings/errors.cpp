// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
#include <pybind11/stl.h>

#include <cfloat>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "bindings.hpp"
#include "tofmat/core/error.hpp"

namespace tofmat::py {

using namespace pybind11::literals;

void register_errors(pyb::module_& m) {
  // A file or stream that does not follow its format is bad input: a ValueError.
  pyb::register_exception<FormatError>(m, "FormatError", PyExc_ValueError);
  pyb::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const IoError& e) {
      // OSError(errno, message) becomes FileNotFoundError, PermissionError, IsADirectoryError...
      // as Python's own file functions raise them; its strerror is the whole message.
      if (e.error_number() != 0) {
        PyObject* args = Py_BuildValue("(is)", e.error_number(), e.what());
        if (args != nullptr) {
          PyErr_SetObject(PyExc_OSError, args);
          Py_DECREF(args);
        }
      } else {
        PyErr_SetString(PyExc_OSError, e.what());
      }
    }
  });
}

namespace {
std::string shape_text(const std::vector<pyb::ssize_t>& shape) {
  std::ostringstream s;
  s << "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i) s << ", ";
    if (shape[i] < 0) {
      s << "any";
    } else {
      s << shape[i];
    }
  }
  if (shape.size() == 1) s << ",";
  s << ")";
  return s.str();
}
}  // namespace

FloatArray as_float32(const pyb::handle& obj, const std::vector<pyb::ssize_t>& shape, const char* what) {
  pyb::array a;
  if (pyb::isinstance<pyb::array>(obj)) {
    a = pyb::reinterpret_borrow<pyb::array>(obj);
  } else {
    // An array-like (nested lists, tuples, numbers): numpy's own conversion to float64, so a
    // list of Python numbers is accepted and a list of strings or None is a TypeError.
    const std::string type_name = pyb::str(pyb::type::of(obj).attr("__name__"));
    try {
      a = pyb::module_::import("numpy").attr("asarray")(obj, "dtype"_a = "float64");
    } catch (const pyb::error_already_set& e) {
      if (!e.matches(PyExc_ValueError) && !e.matches(PyExc_TypeError)) throw;
      throw pyb::type_error(std::string(what) + " must be an array of numbers of shape " + shape_text(shape) +
                            " (a numpy float array, or nested lists of numbers), got a " + type_name +
                            " numpy cannot read as numbers");
    }
  }
  if (a.dtype().kind() != 'f') {
    throw pyb::type_error(std::string(what) +
                          " must have a floating-point dtype (float32 preferred; NaN = missing), got " +
                          std::string(pyb::str(a.dtype())));
  }
  std::vector<pyb::ssize_t> actual(a.shape(), a.shape() + a.ndim());
  bool ok = actual.size() == shape.size();
  for (std::size_t i = 0; ok && i < shape.size(); ++i) ok = shape[i] < 0 || shape[i] == actual[i];
  if (!ok) {
    throw pyb::value_error(std::string(what) + " has shape " + shape_text(actual) + ", expected " + shape_text(shape));
  }
  if (a.dtype().itemsize() > 4) {
    // A float64 value beyond float32's range would silently become Inf in the
    // cast and then be reported as "infinite": name the real problem instead.
    using DoubleArray = pyb::array_t<double, pyb::array::c_style | pyb::array::forcecast>;
    const DoubleArray d = DoubleArray::ensure(a);
    if (!d) throw pyb::error_already_set();
    for (pyb::ssize_t i = 0; i < d.size(); ++i) {
      const double v = d.data()[i];
      if (std::isfinite(v) && std::fabs(v) > static_cast<double>(FLT_MAX)) {
        char text[48];
        std::snprintf(text, sizeof text, "%g", v);
        throw pyb::value_error(std::string(what) + " element " + std::to_string(i) + " = " + text +
                               " is outside the float32 range");
      }
    }
    return FloatArray::ensure(d);
  }
  return FloatArray::ensure(a);
}

}  // namespace tofmat::py
