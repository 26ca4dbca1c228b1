// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The USB transport the driver talks to: the few operations the Kinect v2
// needs (control, bulk, isochronous, alternate settings) behind one small
// interface, so the same driver runs on libusb (libusb_transport.hpp) and on
// the simulated device (firmware/sim/kinect_device.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace tofmat::kinect {

// What went wrong, as distinct kinds the daemon reports differently.
enum class UsbErrorKind {
  kNoDevice,      // nothing with a Kinect v2 ID on the bus
  kPermission,    // found, but this user may not open it (install the udev rule)
  kBusy,          // another program holds its interfaces
  kDisconnected,  // it was there and went away (unplug)
  kTimeout,       // no answer within the timeout
  kStall,         // the endpoint stalled
  kProtocol,      // the device answered something the protocol does not allow
  kIo,            // anything else the USB stack reports
  kCancelled,     // given up because the caller is stopping (DriverOptions::cancel)
};
const char* usb_error_kind_name(UsbErrorKind kind);

class UsbError : public std::runtime_error {
 public:
  UsbError(UsbErrorKind kind, const std::string& what) : std::runtime_error(what), kind_(kind) {}
  UsbErrorKind kind() const { return kind_; }

 private:
  UsbErrorKind kind_;
};

// A completed iso packet: its bytes as received (length 0 allowed).
using IsoPacketHandler = std::function<void(const std::uint8_t* data, std::size_t length)>;

// Opening is a factory's job (open_libusb_kinect, SimulatedKinect::connect):
// it finds, resets, configures and claims the device. Closing is destruction,
// which releases the interfaces and never throws.
class UsbTransport {
 public:
  virtual ~UsbTransport() = default;

  // False once the device has gone (unplug): every call then throws
  // UsbError(kDisconnected). The driver's pump() is where it is noticed first.
  virtual bool connected() const = 0;

  // A human-readable identity ("libusb 2-1 045e:02d8 serial ..." / "sim").
  virtual std::string describe() const = 0;

  // Standard control request with no data stage (SET_FEATURE, SET_ISOCH_DELAY).
  virtual void control(std::uint8_t request_type, std::uint8_t request, std::uint16_t value, std::uint16_t index,
                       unsigned timeout_ms) = 0;
  virtual void set_interface_alt(int interface, int alt) = 0;

  // Bulk transfers; return the bytes moved. A read returns at most `capacity`.
  virtual std::size_t bulk_write(std::uint8_t endpoint, const std::uint8_t* data, std::size_t size,
                                 unsigned timeout_ms) = 0;
  virtual std::size_t bulk_read(std::uint8_t endpoint, std::uint8_t* data, std::size_t capacity,
                                unsigned timeout_ms) = 0;

  // The isochronous endpoint's packet size (wBytesPerInterval).
  virtual std::size_t iso_packet_size(std::uint8_t endpoint) = 0;
  // Keep `transfers` x `packets` iso packets in flight on `endpoint`, handing
  // every completed packet to `on_packet` from handle_events(), until
  // stop_iso(). A packet that did not complete is not handed on.
  virtual void start_iso(std::uint8_t endpoint, int transfers, int packets, IsoPacketHandler on_packet) = 0;
  virtual void stop_iso() = 0;

  // Run completions for up to timeout_ms (the driver's event thread calls it
  // in a loop). Throws UsbError(kDisconnected) once the device has gone.
  virtual void handle_events(unsigned timeout_ms) = 0;
};

}  // namespace tofmat::kinect
