// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmat._tofmat.kinect: the Kinect v2 driver's device listing, and
// tofmat.UsbError (an OSError with a .kind naming what went wrong).
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "tofmat/kinect/libusb_transport.hpp"

namespace tofmat::py {

using kinect::UsbError;

void register_kinect(pyb::module_& parent) {
  static pyb::exception<UsbError> usb_error(parent, "UsbError", PyExc_OSError);
  pyb::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const UsbError& e) {
      const pyb::object type = usb_error;  // call the class, not the deprecated set-error shortcut
      pyb::object inst = type(e.what());
      inst.attr("kind") = kinect::usb_error_kind_name(e.kind());
      PyErr_SetObject(usb_error.ptr(), inst.ptr());
    }
  });
  auto m = parent.def_submodule("kinect", "Kinect v2 driver (firmware/kinect).");
  m.def(
      "list_devices",
      [] {
        std::vector<kinect::UsbDeviceInfo> found;
        {
          pyb::gil_scoped_release nogil;
          found = kinect::list_kinect_devices();
        }
        pyb::list out;
        for (const auto& d : found) {
          pyb::dict e;
          e["bus"] = d.bus;
          e["port"] = d.port;
          e["product_id"] = d.product_id;
          e["serial"] = d.serial;
          e["accessible"] = d.accessible;
          e["problem"] = d.problem;
          out.append(e);
        }
        return out;
      },
      "Every Kinect v2 on the USB bus: dicts of bus, port, product_id, serial, accessible, problem. Raises "
      "UsbError(kind='no device') when libusb cannot start.");
  m.def(
      "open_device",
      [](const std::string& serial) {
        pyb::gil_scoped_release nogil;
        return kinect::open_libusb_kinect(serial)->describe();
      },
      pyb::arg("serial") = "",
      "Open (reset, configure, claim) and close the device; returns its description. Raises UsbError.");
}

}  // namespace tofmat::py
