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
    EXPECT_CONTAINS(std::string(e.what()), "no Kinect v2");
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << "one line";
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
