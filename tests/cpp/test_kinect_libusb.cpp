// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The libusb backend on a machine without a Kinect v2 (CI, this VM): it
// still runs, and fails with the documented error kind and message.
#include <gtest/gtest.h>

#include <string>

#include "test_util.hpp"
#include "tofmat/kinect/libusb_transport.hpp"

namespace {

using namespace tofmat::kinect;

TEST(Libusb, NoDeviceIsAClearError) {
  try {
    open_libusb_kinect();
    FAIL() << "opened a Kinect v2 on a machine that has none";
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kNoDevice) << e.what();
    // One of the two messages docs/kinect-driver.md gives for "no device".
    const std::string what = e.what();
    const bool none_on_bus =
        what == "no Kinect v2 found (USB 045e:02d8 or 045e:02c4); is it plugged into a USB 3 port and powered?";
    const bool no_libusb = what.rfind("no Kinect v2: libusb cannot start on this machine (LIBUSB_ERROR_", 0) == 0;
    EXPECT_TRUE(none_on_bus || no_libusb) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << "one line";
  }
}

TEST(Libusb, AskingForASerialThatIsNotThereIsNoDevice) {
  try {
    open_libusb_kinect("000000000000");
    FAIL();
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kNoDevice);
  }
}

TEST(Libusb, ListingFindsNothingOrSaysLibusbCannotStart) {
  try {
    EXPECT_TRUE(list_kinect_devices().empty());
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kNoDevice);
    EXPECT_CONTAINS(std::string(e.what()), "libusb cannot start");
  }
}

TEST(Libusb, ErrorKindsHaveNames) {
  for (auto k : {UsbErrorKind::kNoDevice, UsbErrorKind::kPermission, UsbErrorKind::kBusy, UsbErrorKind::kDisconnected,
                 UsbErrorKind::kTimeout, UsbErrorKind::kStall, UsbErrorKind::kProtocol, UsbErrorKind::kIo}) {
    EXPECT_STRNE(usb_error_kind_name(k), "?");
  }
  EXPECT_CONTAINS(std::string(kUdevRuleHint), "90-tofmat-kinect2.rules");
}

}  // namespace
