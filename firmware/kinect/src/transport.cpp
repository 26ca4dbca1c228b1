// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The names of the USB error kinds.
#include "tofmat/kinect/transport.hpp"

namespace tofmat::kinect {

const char* usb_error_kind_name(UsbErrorKind kind) {
  switch (kind) {
    case UsbErrorKind::kNoDevice: return "no device";
    case UsbErrorKind::kPermission: return "permission denied";
    case UsbErrorKind::kBusy: return "device busy";
    case UsbErrorKind::kDisconnected: return "disconnected";
    case UsbErrorKind::kTimeout: return "timeout";
    case UsbErrorKind::kStall: return "endpoint stalled";
    case UsbErrorKind::kProtocol: return "protocol error";
    case UsbErrorKind::kIo: return "I/O error";
    case UsbErrorKind::kCancelled: return "cancelled";
  }
  return "?";
}

}  // namespace tofmat::kinect
