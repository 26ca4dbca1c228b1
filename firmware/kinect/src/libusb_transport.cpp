// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The libusb-1.0 UsbTransport: finding and claiming the device, control and bulk transfers, the isochronous pool.
#include "tofmat/kinect/libusb_transport.hpp"

#include <libusb.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <thread>

#include "tofmat/kinect/constants.hpp"

namespace tofmat::kinect {
namespace {

UsbErrorKind kind_of(int rc) {
  switch (rc) {
    case LIBUSB_ERROR_NO_DEVICE: return UsbErrorKind::kDisconnected;
    case LIBUSB_ERROR_ACCESS: return UsbErrorKind::kPermission;
    case LIBUSB_ERROR_BUSY: return UsbErrorKind::kBusy;
    case LIBUSB_ERROR_TIMEOUT: return UsbErrorKind::kTimeout;
    case LIBUSB_ERROR_PIPE: return UsbErrorKind::kStall;
    default: return UsbErrorKind::kIo;
  }
}

[[noreturn]] void fail(int rc, const std::string& what) {
  std::string msg = what + ": " + libusb_error_name(rc);
  if (rc == LIBUSB_ERROR_ACCESS) msg += "; " + std::string(kUdevRuleHint);
  throw UsbError(kind_of(rc), msg);
}

void check(int rc, const std::string& what) {
  if (rc < 0) fail(rc, what);
}

struct Context {
  libusb_context* ctx = nullptr;
  Context() {
    const int rc = libusb_init(&ctx);
    if (rc < 0) {
      throw UsbError(UsbErrorKind::kNoDevice,
                     std::string("no Kinect v2: libusb cannot start on this machine (") + libusb_error_name(rc) + ")");
    }
  }
  ~Context() {
    if (ctx) libusb_exit(ctx);
  }
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;
};

bool is_kinect(libusb_device* d, std::uint16_t* pid) {
  libusb_device_descriptor desc{};
  if (libusb_get_device_descriptor(d, &desc) < 0) return false;
  if (desc.idVendor != kVendorId || (desc.idProduct != kProductId && desc.idProduct != kProductIdPreview)) return false;
  if (pid) *pid = desc.idProduct;
  return true;
}

std::string port_of(libusb_device* d) {
  std::uint8_t ports[8];
  const int n = libusb_get_port_numbers(d, ports, 8);
  std::string s = std::to_string(libusb_get_bus_number(d)) + "-";
  for (int i = 0; i < n; ++i) s += (i ? "." : "") + std::to_string(ports[i]);
  return s;
}

std::string serial_of(libusb_device_handle* h, libusb_device* d) {
  libusb_device_descriptor desc{};
  if (libusb_get_device_descriptor(d, &desc) < 0 || desc.iSerialNumber == 0) return "";
  unsigned char buf[128];
  const int n = libusb_get_string_descriptor_ascii(h, desc.iSerialNumber, buf, sizeof buf);
  return n > 0 ? std::string(reinterpret_cast<char*>(buf), static_cast<std::size_t>(n)) : "";
}

// wBytesPerInterval of the depth endpoint (config 1, interface 1, alt 1).
std::size_t iso_size_of(libusb_context* ctx, libusb_device* d) {
  libusb_config_descriptor* config = nullptr;
  check(libusb_get_config_descriptor_by_value(d, kConfiguration, &config), "reading the configuration descriptor");
  std::size_t size = 0;
  if (config->bNumInterfaces > kDepthInterface) {
    const libusb_interface& itf = config->interface[kDepthInterface];
    if (itf.num_altsetting > kDepthAltStreaming) {
      const libusb_interface_descriptor& alt = itf.altsetting[kDepthAltStreaming];
      for (int e = 0; e < alt.bNumEndpoints; ++e) {
        if (alt.endpoint[e].bEndpointAddress != kDepthIsoEndpoint) continue;
        libusb_ss_endpoint_companion_descriptor* comp = nullptr;
        if (libusb_get_ss_endpoint_companion_descriptor(ctx, &alt.endpoint[e], &comp) == 0) {
          size = comp->wBytesPerInterval;
          libusb_free_ss_endpoint_companion_descriptor(comp);
        }
      }
    }
  }
  libusb_free_config_descriptor(config);
  return size;
}

class LibusbTransport final : public UsbTransport {
 public:
  LibusbTransport(std::unique_ptr<Context> ctx, libusb_device_handle* h, std::string description)
      : ctx_(std::move(ctx)), h_(h), description_(std::move(description)) {}

  ~LibusbTransport() override {
    try {
      stop_iso();
    } catch (const std::exception&) {
    }
    libusb_release_interface(h_, kDepthInterface);
    libusb_release_interface(h_, kControlInterface);
    libusb_close(h_);
  }

  std::string describe() const override { return description_; }
  bool connected() const override { return !disconnected_; }

  void control(std::uint8_t request_type, std::uint8_t request, std::uint16_t value, std::uint16_t index,
               unsigned timeout_ms) override {
    gone();
    check(libusb_control_transfer(h_, request_type, request, value, index, nullptr, 0, timeout_ms), "control request");
  }

  void set_interface_alt(int interface, int alt) override {
    gone();
    check(libusb_set_interface_alt_setting(h_, interface, alt), "selecting alternate setting " + std::to_string(alt));
  }

  std::size_t bulk_write(std::uint8_t ep, const std::uint8_t* data, std::size_t size, unsigned timeout_ms) override {
    gone();
    int done = 0;
    check(libusb_bulk_transfer(h_, ep, const_cast<std::uint8_t*>(data), static_cast<int>(size), &done, timeout_ms),
          "command write");
    return static_cast<std::size_t>(done);
  }

  std::size_t bulk_read(std::uint8_t ep, std::uint8_t* data, std::size_t capacity, unsigned timeout_ms) override {
    gone();
    int done = 0;
    check(libusb_bulk_transfer(h_, ep, data, static_cast<int>(capacity), &done, timeout_ms), "response read");
    return static_cast<std::size_t>(done);
  }

  std::size_t iso_packet_size(std::uint8_t) override {
    gone();
    return iso_size_of(ctx_->ctx, libusb_get_device(h_));
  }

  void start_iso(std::uint8_t ep, int transfers, int packets, IsoPacketHandler on_packet) override {
    gone();
    handler_ = std::move(on_packet);
    const std::size_t size = iso_packet_size(ep);
    if (size == 0) throw UsbError(UsbErrorKind::kProtocol, "depth endpoint has no SuperSpeed companion descriptor");
    stopping_ = false;
    for (int k = 0; k < transfers; ++k) {
      Slot s;
      s.buffer.resize(size * static_cast<std::size_t>(packets));
      s.transfer = libusb_alloc_transfer(packets);
      if (!s.transfer) throw UsbError(UsbErrorKind::kIo, "cannot allocate an iso transfer");
      slots_.push_back(std::move(s));
    }
    for (auto& s : slots_) {
      libusb_fill_iso_transfer(s.transfer, h_, ep, s.buffer.data(), static_cast<int>(s.buffer.size()), packets,
                               &LibusbTransport::on_transfer, this, kTimeoutMs);
      libusb_set_iso_packet_lengths(s.transfer, static_cast<unsigned>(size));
      check(libusb_submit_transfer(s.transfer), "submitting iso transfers");
      ++in_flight_;
    }
  }

  void stop_iso() override {
    if (slots_.empty()) return;
    stopping_ = true;
    for (auto& s : slots_) libusb_cancel_transfer(s.transfer);
    // Every transfer must call back before its memory goes.
    for (int k = 0; k < 1000 && in_flight_ > 0; ++k) {
      timeval tv{0, 10000};
      libusb_handle_events_timeout_completed(ctx_->ctx, &tv, nullptr);
    }
    if (in_flight_ > 0) {
      // A transfer that never called back may still be written by libusb:
      // leak the slots (transfers and buffers) rather than free memory in use.
      new std::vector<Slot>(std::move(slots_));
    } else {
      for (auto& s : slots_) libusb_free_transfer(s.transfer);
    }
    slots_.clear();
    handler_ = nullptr;
  }

  void handle_events(unsigned timeout_ms) override {
    gone();
    timeval tv{static_cast<time_t>(timeout_ms / 1000), static_cast<suseconds_t>((timeout_ms % 1000) * 1000)};
    check(libusb_handle_events_timeout_completed(ctx_->ctx, &tv, nullptr), "USB events");
    gone();
    // Every transfer failed to go back in flight: the stream has stopped
    // without the device going away. Say so instead of waiting for frames.
    if (!slots_.empty() && !stopping_ && in_flight_ == 0) {
      throw UsbError(UsbErrorKind::kIo, std::string("depth stream stopped: no iso transfer could be resubmitted (") +
                                            libusb_error_name(last_resubmit_error_) + ")");
    }
  }

 private:
  struct Slot {
    libusb_transfer* transfer = nullptr;
    std::vector<std::uint8_t> buffer;
  };

  static void LIBUSB_CALL on_transfer(libusb_transfer* t) {
    auto* self = static_cast<LibusbTransport*>(t->user_data);
    if (t->status == LIBUSB_TRANSFER_NO_DEVICE) self->disconnected_ = true;
    if (t->status == LIBUSB_TRANSFER_COMPLETED && self->handler_) {
      for (int i = 0; i < t->num_iso_packets; ++i) {
        const auto& d = t->iso_packet_desc[i];
        if (d.status != LIBUSB_TRANSFER_COMPLETED) continue;  // not handed on (1.2)
        self->handler_(libusb_get_iso_packet_buffer_simple(t, static_cast<unsigned>(i)), d.actual_length);
      }
    }
    if (!self->stopping_ && !self->disconnected_) {
      const int r = libusb_submit_transfer(t);
      if (r == 0) return;
      self->last_resubmit_error_ = r;
      if (r == LIBUSB_ERROR_NO_DEVICE) self->disconnected_ = true;
    }
    --self->in_flight_;
  }

  void gone() const {
    if (disconnected_) throw UsbError(UsbErrorKind::kDisconnected, "Kinect v2 disconnected (" + description_ + ")");
  }

  std::unique_ptr<Context> ctx_;
  libusb_device_handle* h_;
  std::string description_;
  IsoPacketHandler handler_;
  std::vector<Slot> slots_;
  std::atomic<int> in_flight_{0};
  std::atomic<bool> stopping_{false}, disconnected_{false};
  std::atomic<int> last_resubmit_error_{0};
};

// Finds and opens (without the port reset) the device matching `serial`.
libusb_device_handle* find_and_open(libusb_context* ctx, const std::string& serial, std::string* description) {
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(ctx, &list);
  if (n < 0) fail(static_cast<int>(n), "listing USB devices");
  libusb_device_handle* found = nullptr;
  int seen = 0, last_error = 0;
  std::string where;
  for (ssize_t i = 0; i < n && !found; ++i) {
    std::uint16_t pid = 0;
    if (!is_kinect(list[i], &pid)) continue;
    ++seen;
    libusb_device_handle* h = nullptr;
    const int rc = libusb_open(list[i], &h);
    where = "Kinect v2 at " + port_of(list[i]);
    if (rc < 0) {
      last_error = rc;
      continue;
    }
    const std::string s = serial_of(h, list[i]);
    if (!serial.empty() && s != serial) {
      libusb_close(h);
      continue;
    }
    char pidbuf[8];
    std::snprintf(pidbuf, sizeof pidbuf, "%04x", pid);
    *description = "libusb " + port_of(list[i]) + " 045e:" + pidbuf + " serial " + (s.empty() ? "?" : s);
    found = h;
  }
  libusb_free_device_list(list, 1);
  if (found) return found;
  if (seen == 0) {
    throw UsbError(UsbErrorKind::kNoDevice,
                   "no Kinect v2 found (USB 045e:02d8 or 045e:02c4); is it plugged into a USB 3 port and powered?");
  }
  if (last_error) fail(last_error, "cannot open the " + where);
  throw UsbError(UsbErrorKind::kNoDevice,
                 "no Kinect v2 with serial " + serial + " (" + std::to_string(seen) + " other(s) found)");
}

}  // namespace

std::vector<UsbDeviceInfo> list_kinect_devices() {
  Context c;
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(c.ctx, &list);
  if (n < 0) fail(static_cast<int>(n), "listing USB devices");
  std::vector<UsbDeviceInfo> out;
  for (ssize_t i = 0; i < n; ++i) {
    UsbDeviceInfo info;
    if (!is_kinect(list[i], &info.product_id)) continue;
    info.bus = libusb_get_bus_number(list[i]);
    info.port = port_of(list[i]);
    libusb_device_handle* h = nullptr;
    const int rc = libusb_open(list[i], &h);
    if (rc == 0) {
      info.serial = serial_of(h, list[i]);
      info.accessible = true;
      libusb_close(h);
    } else {
      info.problem =
          std::string(libusb_error_name(rc)) + (rc == LIBUSB_ERROR_ACCESS ? std::string("; ") + kUdevRuleHint : "");
    }
    out.push_back(std::move(info));
  }
  libusb_free_device_list(list, 1);
  return out;
}

std::unique_ptr<UsbTransport> open_libusb_kinect(const std::string& serial) {
  auto ctx = std::make_unique<Context>();
  std::string description;
  libusb_device_handle* h = find_and_open(ctx->ctx, serial, &description);
  // 1.3 step 1: a port reset; if the device re-enumerates, find it again.
  if (libusb_reset_device(h) == LIBUSB_ERROR_NOT_FOUND) {
    libusb_close(h);
    std::this_thread::sleep_for(std::chrono::seconds(1));
    h = find_and_open(ctx->ctx, serial, &description);
  }
  int current = 0;
  int rc = libusb_get_configuration(h, &current);
  if (rc == 0 && current != kConfiguration) rc = libusb_set_configuration(h, kConfiguration);
  if (rc == 0) rc = libusb_claim_interface(h, kControlInterface);
  if (rc == 0) rc = libusb_claim_interface(h, kDepthInterface);
  if (rc < 0) {
    libusb_close(h);
    fail(rc, rc == LIBUSB_ERROR_BUSY ? "the Kinect v2 is in use by another program" : "cannot claim the Kinect v2");
  }
  return std::make_unique<LibusbTransport>(std::move(ctx), h, description);
}

}  // namespace tofmat::kinect
