// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// make_source: the frame source named by a `--source` spec (kinect, sim or replay).
#include "tofmat/daemon/source.hpp"

#include <stdexcept>

#include "tofmat/daemon/device_source.hpp"
#include "tofmat/daemon/recording.hpp"
#ifdef TOFMAT_DAEMON_WITH_SIM
#include "tofmat/daemon/sim_source.hpp"
#endif
#ifdef TOFMAT_DAEMON_WITH_LIBUSB
#include "tofmat/kinect/libusb_transport.hpp"
#endif

namespace tofmat::daemon {

std::unique_ptr<Source> make_source(const std::string& spec, const SourceOptions& options) {
  const auto colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string rest = colon == std::string::npos ? "" : spec.substr(colon + 1);
  if (kind == "sim") {
#ifdef TOFMAT_DAEMON_WITH_SIM
    return make_sim_source(parse_sim_spec(rest), options);
#else
    throw std::invalid_argument("this tofmatd was built without the simulator");
#endif
  }
  if (kind == "kinect") {
#ifdef TOFMAT_DAEMON_WITH_LIBUSB
    const std::string& serial = rest;
    return std::make_unique<DeviceSource>(
        serial.empty() ? "Kinect v2 (libusb)" : "Kinect v2 " + serial + " (libusb)",
        [serial] { return kinect::open_libusb_kinect(serial); }, nullptr, options.retry_ms,
        /*simulated=*/false);
#else
    throw std::invalid_argument("this tofmatd was built without libusb");
#endif
  }
  if (kind == "replay") return make_replay_source(rest);
  throw std::invalid_argument("unknown source \"" + spec + "\" (kinect[:SERIAL], sim[:SCENE,...], replay:FILE)");
}

}  // namespace tofmat::daemon
