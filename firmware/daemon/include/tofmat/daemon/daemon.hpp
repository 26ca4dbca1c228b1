// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd put together: the source on the USB/event thread, the pipeline on
// the processing thread, the server on its own thread, and the command
// handler that joins clients to the pipeline. The caller's thread handles
// signals (main.cpp): stop() on SIGTERM/SIGINT, reload_table() on SIGHUP.
#pragma once
#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "tofmat/daemon/pipeline.hpp"
#include "tofmat/daemon/reset_button.hpp"
#include "tofmat/daemon/server.hpp"
#include "tofmat/daemon/sorting_line.hpp"
#include "tofmat/daemon/source.hpp"

namespace tofmat::daemon {

struct DaemonOptions {
  // The camera: a box that was misconfigured must never serve simulated
  // labels, so the simulator is only ever a source asked for by name.
  std::string source = "kinect";
  std::string table;  // .tmx (or a folder of <material>.npy)
  // Where a client's load_table may read from ("" = the folder holding
  // `table`): names resolve inside it, and nothing outside it is opened.
  std::string table_dir;
  ProfileConfig profile;
  ServerOptions server;
  SourceOptions source_options;
  std::size_t queue_frames = 2;
  // The sorting line on GPIO (line.gpio "" = none): needs the sorting profile.
  LineOptions line;
  // The front panel's reset button on GPIO (line.gpio's backend).
  ButtonOptions button;
};

// A table file (.tmx) or a folder of the real database's .npy files.
std::shared_ptr<const ExemplarTable> load_table_file(const std::string& path);

class Daemon {
 public:
  // Loads the table, opens the sockets and the source. Throws with a
  // message for people on any bad option (nothing is left running).
  explicit Daemon(DaemonOptions options);
  ~Daemon();
  void start();
  void stop();
  // Whether a thread the daemon cannot do without (server, processing) ended on an error.
  bool failed() const { return failed_; }
  // SIGHUP: the table file again (the current path); a table that does not
  // load or does not fit the profile is refused and the old one keeps serving.
  bool reload_table();
  protocol::Reply handle(const protocol::Request& request);
  nlohmann::json status() const;
  Server& server() { return *server_; }

 private:
  DaemonOptions options_;
  std::unique_ptr<Pipeline> pipeline_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<Source> source_;
  std::unique_ptr<SortingLine> line_;    // null without a sorting line
  std::unique_ptr<ResetButton> button_;  // null without a reset button
  std::atomic<bool> stop_{false};
  std::atomic<bool> failed_{false};
  void fail(const std::string& why);
  // A `reset` event: the accumulation started over (`by`: "button" or "command").
  void publish_reset(const char* by, std::uint64_t timestamp_ns);
  std::thread source_thread_, pipeline_thread_, server_thread_, line_thread_, button_thread_;
  std::uint64_t started_ns_ = 0;
  mutable std::mutex state_mutex_;
  DeviceState device_state_ = DeviceState::kOpening;
  std::string device_message_;
  std::uint64_t device_changes_ = 0;
  nlohmann::json last_reload_ = nullptr;
};

}  // namespace tofmat::daemon
