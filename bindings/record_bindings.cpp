// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmat record: a source of tofmatd (kinect, sim, replay) run in-process,
// its first frames written to a recording that `--source replay:FILE` plays.
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "bindings.hpp"
#include "core_log.hpp"
#include "tofmat/daemon/recording.hpp"

namespace tofmat::py {
namespace {

struct RecordResult {
  std::uint64_t frames = 0;
  std::string last_state;
};

RecordResult record(const std::string& source_spec, const std::string& path, std::uint64_t frames,
                    const std::string& sim_data_dir, double timeout_s) {
  if (frames == 0) throw pyb::value_error("frames must be at least 1");
  if (!(timeout_s > 0.0 && timeout_s <= 1e7)) throw pyb::value_error("timeout must be a number of seconds in (0, 1e7]");
  daemon::SourceOptions options;
  options.sim_data_dir = sim_data_dir;
  auto source = daemon::make_source(source_spec, options);
  std::unique_ptr<daemon::RecordingWriter> writer;
  std::atomic<bool> stop{false};
  std::mutex mutex;
  std::condition_variable done;
  RecordResult result;
  std::string error;
  daemon::SourceCallbacks cb;
  cb.frame = [&](daemon::RawFrame&& f) {
    std::lock_guard<std::mutex> lock(mutex);
    if (stop.load() || !error.empty()) return;
    try {
      if (!writer)
        writer = std::make_unique<daemon::RecordingWriter>(path, f.calibration->p0_rad, f.simulated,
                                                           f.calibration->intrinsics);
      writer->write(f);
      if (++result.frames >= frames) stop = true;
    } catch (const std::exception& e) {
      error = e.what();
      stop = true;
    }
    done.notify_all();
  };
  cb.state = [&](daemon::DeviceState s, const std::string& message) {
    std::lock_guard<std::mutex> lock(mutex);
    result.last_state = std::string(daemon::device_state_name(s)) + ": " + message;
    if (s == daemon::DeviceState::kStopped) done.notify_all();
  };
  {
    pyb::gil_scoped_release release;
    std::thread t([&] { source->run(cb, stop); });
    const auto deadline =
        std::chrono::steady_clock::now() +
        std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(timeout_s));
    std::unique_lock<std::mutex> lock(mutex);
    while (!stop.load() && std::chrono::steady_clock::now() < deadline) {
      // Wakes every 200 ms to hand the source's logs to Python while it runs.
      done.wait_until(lock, std::min(deadline, std::chrono::steady_clock::now() + std::chrono::milliseconds(200)),
                      [&] { return stop.load(); });
      lock.unlock();
      {
        pyb::gil_scoped_acquire gil;
        forward_core_logs();
      }
      lock.lock();
    }
    stop = true;
    lock.unlock();
    t.join();
  }
  forward_core_logs();
  const std::string problem = take_last_core_problem();
  if (!error.empty()) throw std::runtime_error("recording failed: " + error);
  if (writer) writer->close();
  if (result.frames < frames)
    throw std::runtime_error("recorded " + std::to_string(result.frames) + " of " + std::to_string(frames) +
                             " frames before the timeout" +
                             (problem.empty() ? " (" + result.last_state + ")" : ": " + problem));
  return result;
}

}  // namespace

void register_record(pyb::module_& m) {
  m.def(
      "record",
      [](const std::string& source, const std::string& path, std::uint64_t frames, const std::string& sim_data_dir,
         double timeout) { return record(source, path, frames, sim_data_dir, timeout).frames; },
      pyb::arg("source"), pyb::arg("path"), pyb::arg("frames"), pyb::arg("sim_data_dir"), pyb::arg("timeout") = 60.0,
      "Runs a tofmatd source and writes its first `frames` frames to a recording; returns the count.");
}

}  // namespace tofmat::py
