// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The UsbTransport on libusb-1.0: finds a Kinect v2 (either product ID),
// resets, configures and claims it, and keeps a pool of isochronous transfers
// in flight on the depth endpoint (kinect2-protocol.md 1.1-1.3). Each failure
// becomes a UsbError of a distinct kind with a one-line reason.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "tofmat/kinect/transport.hpp"

namespace tofmat::kinect {

struct UsbDeviceInfo {
  int bus = 0;
  std::string port;  // "2-1.3"
  std::uint16_t product_id = 0;
  std::string serial;  // empty when the device could not be opened to read it
  bool accessible = false;
  std::string problem;  // why not accessible (permission, busy, ...)
};

// Every Kinect v2 on the bus. Throws UsbError(kNoDevice) if libusb cannot
// start (no USB on this machine).
std::vector<UsbDeviceInfo> list_kinect_devices();

// Opens the device with this serial (empty: the first one found). Throws
// UsbError: kNoDevice, kPermission (names the udev rule), kBusy, kIo.
std::unique_ptr<UsbTransport> open_libusb_kinect(const std::string& serial = "");

// Where the udev rule lives in the repository and the one-line fix it offers.
inline constexpr const char* kUdevRuleHint =
    "install firmware/kinect/udev/90-tofmat-kinect2.rules into /etc/udev/rules.d and replug "
    "(docs/kinect-driver.md)";

}  // namespace tofmat::kinect
