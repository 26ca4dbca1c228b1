#include <pybind11/stl.h>

#include <cfloat>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "bindings.hpp"
#include "tofmat/core/error.hpp"

namespace tofmat::py {

void register_errors(pyb::module_& m) {
  // A file or stream that does not follow its format is bad input: a ValueError.
  pyb::register_exception<FormatError>(m, "FormatError", PyExc_ValueError);
  pyb::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const IoError& e) {
      PyErr_SetString(PyExc_OSError, e.what());
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

FloatArray as_float32(const pyb::handle& obj, const std::vector<pyb::ssize_t>& shape,
                                                     const char* what) {
  if (!pyb::isinstance<pyb::array>(obj)) {
    throw pyb::value_error(std::string(what) + " must be a numpy float array of shape " + shape_text(shape) +
                           ", got " + std::string(pyb::str(pyb::type::of(obj).attr("__name__"))));
  }
  auto a = pyb::reinterpret_borrow<pyb::array>(obj);
  if (a.dtype().kind() != 'f') {
    throw pyb::value_error(std::string(what) + " must have a floating-point dtype (float32 preferred; NaN = missing), got " +
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
