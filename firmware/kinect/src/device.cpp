// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Kinect2Device: the open, start, stop and close sequences and the command transactions over a UsbTransport.
#include "tofmat/kinect/device.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

#include "tofmat/core/error.hpp"

namespace tofmat::kinect {
namespace {

// Standard requests (USB 3.0 chapter 9) the open and start sequences send.
constexpr std::uint8_t kToDevice = 0x00, kToInterface = 0x01;
constexpr std::uint8_t kSetFeature = 0x03, kSetIsochDelay = 0x31;
constexpr std::uint16_t kU1Enable = 48, kU2Enable = 49, kFunctionSuspend = 0;
constexpr std::uint16_t kIsochDelayNs = 40;

void function_suspend(UsbTransport& t, std::uint16_t options, unsigned timeout_ms) {
  t.control(kToInterface, kSetFeature, kFunctionSuspend, static_cast<std::uint16_t>(options << 8 | kControlInterface),
            timeout_ms);
}

std::string hex_id(std::uint32_t id) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%02X", id);
  return buf;
}

}  // namespace

Kinect2Device::Kinect2Device(std::unique_ptr<UsbTransport> transport, DriverOptions options)
    : transport_(std::move(transport)), options_(options) {
  if (!transport_) throw std::invalid_argument("Kinect2Device needs a transport");
  if (options_.retries < 0 || options_.retries > 10 || options_.status_polls < 1 || options_.iso_transfers < 1 ||
      options_.iso_packets < 1) {
    throw std::invalid_argument("driver options out of range");
  }
}

Kinect2Device::~Kinect2Device() {
  try {
    close();
  } catch (const std::exception&) {
    // Closing a device that is gone fails; there is nobody left to tell.
  }
}

void Kinect2Device::open() {
  auto& t = *transport_;
  t.control(kToDevice, kSetIsochDelay, kIsochDelayNs, 0, options_.timeout_ms);
  t.set_interface_alt(kDepthInterface, kDepthAltOff);
  t.control(kToDevice, kSetFeature, kU1Enable, 0, options_.timeout_ms);
  t.control(kToDevice, kSetFeature, kU2Enable, 0, options_.timeout_ms);
  function_suspend(t, 3, options_.timeout_ms);  // low power + remote wake until started
  const std::size_t iso = t.iso_packet_size(kDepthIsoEndpoint);
  if (iso < kMinIsoPacketBytes) {
    throw UsbError(UsbErrorKind::kProtocol, "depth endpoint packet size " + std::to_string(iso) + " is below " +
                                                std::to_string(kMinIsoPacketBytes) + ": not a USB 3 link?");
  }
  opened_ = true;
}

std::vector<std::uint8_t> Kinect2Device::transact(const Command& command) {
  auto& t = *transport_;
  for (int attempt = 0;; ++attempt) {
    const std::uint32_t seq = next_sequence_++;
    ++counters_.commands;
    try {
      const auto out = encode_command(command, seq);
      if (t.bulk_write(kCommandOutEndpoint, out.data(), out.size(), options_.timeout_ms) != out.size()) {
        throw UsbError(UsbErrorKind::kProtocol,
                       "short write of command " + hex_id(static_cast<std::uint32_t>(command.id)));
      }
      std::vector<std::uint8_t> response;
      if (command.max_response > 0) {
        response.resize(command.max_response);
        response.resize(t.bulk_read(kResponseInEndpoint, response.data(), response.size(), options_.timeout_ms));
        if (looks_like_completion(response.data(), response.size())) {
          throw UsbError(UsbErrorKind::kProtocol,
                         "premature completion of command " + hex_id(static_cast<std::uint32_t>(command.id)));
        }
      }
      // Completions of earlier commands that timed out may still be queued,
      // and their late responses, up to the largest a command has: skip a
      // few, bounded, before calling the exchange broken. (A smaller buffer
      // would make a long late response a USB overflow error.)
      late_.resize(kMaxResponseBytes);
      for (int k = 0; k < 8; ++k) {
        check_cancel();
        const std::size_t n = t.bulk_read(kResponseInEndpoint, late_.data(), late_.size(), options_.timeout_ms);
        Completion c;
        try {
          c = parse_completion(late_.data(), n);
        } catch (const FormatError&) {
          ++counters_.stale_completions;  // a late response of an earlier command
          continue;
        }
        if (c.sequence == seq) return response;
        if (c.sequence < seq) {
          ++counters_.stale_completions;
          continue;
        }
        throw UsbError(UsbErrorKind::kProtocol, "completion for sequence " + std::to_string(c.sequence) +
                                                    " while waiting for " + std::to_string(seq));
      }
      throw UsbError(UsbErrorKind::kProtocol, "no completion for sequence " + std::to_string(seq));
    } catch (const UsbError& e) {
      if (e.kind() != UsbErrorKind::kTimeout || attempt >= options_.retries) throw;
      check_cancel();
      ++counters_.retries;
    }
  }
}

void Kinect2Device::check_cancel() const {
  if (options_.cancel && options_.cancel->load()) throw UsbError(UsbErrorKind::kCancelled, "stopping");
}

void Kinect2Device::wait_until_ready() {
  for (int k = 0; k < options_.status_polls; ++k) {
    const auto r = transact(cmd_read_status());
    std::uint32_t status = 0;
    try {
      status = parse_status(r.data(), r.size());
    } catch (const FormatError& e) {
      throw UsbError(UsbErrorKind::kProtocol, e.what());
    }
    if (status & 1u) return;
    // (In slices: a stop is seen within 20 ms.)
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(options_.status_poll_ms);
    while (std::chrono::steady_clock::now() < until) {
      check_cancel();
      std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(
          std::chrono::milliseconds(20), until - std::chrono::steady_clock::now()));
    }
  }
  throw UsbError(UsbErrorKind::kTimeout,
                 "device not ready to stream after " + std::to_string(options_.status_polls) + " status polls");
}

const DeviceIdentity& Kinect2Device::start(FrameHandler on_frame) {
  if (!opened_) open();
  if (streaming_) throw std::logic_error("Kinect2Device::start: already streaming");
  auto& t = *transport_;
  function_suspend(t, 0, options_.timeout_ms);
  try {
    const auto fw = transact(cmd_read_firmware_versions());
    const auto versions = parse_firmware_versions(fw.data(), fw.size());
    identity_.firmware = versions.size() > 3 ? versions[3].to_string() : versions.back().to_string();
    transact(cmd_read_hardware_info());
    const auto serial = transact(cmd_read_data_page(kPageSerial));
    identity_.serial = parse_serial(serial.data(), serial.size());
    const auto depth = transact(cmd_read_data_page(kPageDepthParams));
    identity_.depth = parse_depth_params(depth.data(), depth.size());
    const auto p0 = transact(cmd_read_data_page(kPageP0Tables));
    identity_.p0 = parse_p0_tables(p0.data(), p0.size());
    transact(cmd_read_data_page(kPageColorParams));
  } catch (const FormatError& e) {
    throw UsbError(UsbErrorKind::kProtocol, std::string("start-up response: ") + e.what());
  }
  transact(cmd_set_mode(true, 0x00640064));
  transact(cmd_set_mode(false));
  wait_until_ready();
  transact(cmd_init_streams());
  t.set_interface_alt(kDepthInterface, kDepthAltStreaming);
  // The parser before the stream starts: a packet size it cannot work with
  // fails here, before the device is left streaming.
  parser_ = std::make_unique<DepthStreamParser>(t.iso_packet_size(kDepthIsoEndpoint), std::move(on_frame));
  DepthStreamParser* parser = parser_.get();
  transact(cmd_read_status());
  transact(cmd_set_streaming(true));
  t.start_iso(kDepthIsoEndpoint, options_.iso_transfers, options_.iso_packets,
              [parser](const std::uint8_t* data, std::size_t length) { parser->feed(data, length); });
  streaming_ = true;
  return identity_;
}

void Kinect2Device::pump(unsigned timeout_ms) { transport_->handle_events(timeout_ms); }

DepthStreamCounters Kinect2Device::stream_counters() const {
  return parser_ ? parser_->counters() : DepthStreamCounters{};
}

void Kinect2Device::stop() {
  if (!streaming_) return;
  streaming_ = false;
  auto& t = *transport_;
  t.stop_iso();
  t.set_interface_alt(kDepthInterface, kDepthAltOff);
  transact(cmd_set_mode(true, 0x00640064));
  transact(cmd_set_mode(false));
  transact(cmd_stop());
  transact(cmd_set_streaming(false));
  for (int k = 0; k < 2; ++k) {
    transact(cmd_set_mode(true));
    transact(cmd_set_mode(false));
  }
  function_suspend(t, 3, options_.timeout_ms);
}

void Kinect2Device::close() {
  if (!opened_) return;
  stop();
  opened_ = false;
  transact(cmd_set_mode(true, 0x00640064));
  transact(cmd_set_mode(false));
  transact(cmd_shutdown());
}

}  // namespace tofmat::kinect
