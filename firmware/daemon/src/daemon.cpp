// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Daemon: starts and stops the source, pipeline, server, sorting line and reset button, and handles clients' commands.
#include "tofmat/daemon/daemon.hpp"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <filesystem>

#include "tofmat/core/table_file.hpp"
#include "tofmat/daemon/log.hpp"
#include "tofmat/gpio/sim_gpio.hpp"

namespace tofmat::daemon {
namespace {

constexpr const char* kVersion = "tofmatd 0.1.0";

protocol::Reply failure(std::uint32_t id, const char* code, const std::string& why) {
  protocol::Reply r;
  r.id = id;
  r.ok = false;
  r.code = code;
  r.error = why;
  return r;
}

}  // namespace

std::shared_ptr<const ExemplarTable> load_table_file(const std::string& path) {
  if (std::filesystem::is_directory(path))
    return std::make_shared<const ExemplarTable>(
        ExemplarTable::from_npy_dir(path, kDatabaseBinStartMm, kDatabaseBinStopMm));
  auto table = std::make_shared<const ExemplarTable>(load_table(path));
  check_measured(*table, path);  // (a folder's are checked as it is read)
  return table;
}

// A client's table name resolved inside `dir` (canonical: the daemon made
// it so at start), symlinks followed, or a refusal that says the same
// whether or not the file exists; any doubt (a path that cannot be
// resolved) is a refusal.
std::string table_in(const std::string& dir, const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path base(dir);
  std::error_code ec;
  const fs::path real = fs::weakly_canonical(fs::path(name).is_absolute() ? fs::path(name) : base / name, ec);
  const auto [end, rest] = std::mismatch(base.begin(), base.end(), real.begin(), real.end());
  if (ec || name.empty() || base.empty() || end != base.end() || rest == real.end())
    throw std::invalid_argument("table \"" + name + "\" is not in the table directory " + dir +
                                " (load_table reads only from there: --table-dir)");
  return real.string();
}

Daemon::Daemon(DaemonOptions options) : options_(std::move(options)) {
  // The table directory, canonical once (load_table compares paths with it).
  if (options_.table_dir.empty())
    options_.table_dir = std::filesystem::absolute(options_.table).lexically_normal().parent_path().string();
  options_.table_dir = std::filesystem::weakly_canonical(options_.table_dir).string();
  options_.server.server_name = kVersion;
  options_.server.capabilities = {"labels",      "label_map", "depth",          "device",     "status",  "reset",
                                  "set_profile", "set_roi",   "set_candidates", "load_table", "trigger", "latest"};
  if (options_.line.enabled())
    options_.server.capabilities.insert(options_.server.capabilities.end(), {"sort", "line"});
  // The table, the profile and the source are checked before the sockets
  // listen: a client never connects to a daemon that is about to refuse its
  // start (none of them opens the camera yet, so a second daemon on a live
  // one's socket disturbs nothing before the socket refuses it).
  auto table = load_table_file(options_.table);
  pipeline_ = std::make_unique<Pipeline>(table, options_.table, options_.profile, options_.queue_frames);
  // --gpio sim: one simulated chip, the line's and the simulated belt's (sim:belt drives its barrier).
  const auto gpio_backend = options_.line.gpio.empty() ? nullptr : make_gpio_backend(options_.line.gpio);
  options_.source_options.sim_gpio = std::dynamic_pointer_cast<gpio::SimGpio>(gpio_backend);
  source_ = make_source(options_.source, options_.source_options);
  if (options_.line.enabled()) {
    if (options_.profile.name != "sorting")
      throw std::invalid_argument("the sorting line (--gpio) needs --profile sorting, not " + options_.profile.name);
    SortingLine::Hooks hooks;
    hooks.start_burst = [this](std::string& why) -> std::optional<std::uint64_t> {
      try {
        return pipeline_->trigger(0);
      } catch (const std::exception& e) {  // (a client switched the profile away from sorting)
        why = e.what();
        return std::nullopt;
      }
    };
    hooks.publish = [this](const protocol::Message& m, const std::string& stream) { server_->publish(stream, m); };
    hooks.item_truth = [this](std::uint64_t trigger_ns) { return source_->item_truth(trigger_ns); };
    line_ = std::make_unique<SortingLine>(options_.line, gpio_backend, table->distinct_materials(), std::move(hooks));
  }
  if (options_.button.enabled())
    button_ = std::make_unique<ResetButton>(options_.button, gpio_backend, [this](std::uint64_t t) {
      pipeline_->reset();
      server_->forget("labels");
      publish_reset("button", t);
    });
  // (requests are only handled once start() runs)
  server_ = std::make_unique<Server>(options_.server, [this](const protocol::Request& r) { return handle(r); });
  Emitter emit;
  emit.label = [this](const protocol::LabelEvent& e) {
    if (line_) line_->label(e);
    server_->publish("labels", protocol::encode_label_wire(e));
  };
  emit.label_map = [this](const protocol::LabelMapEvent& e) {
    server_->publish("label_map", protocol::encode_label_map(e));
  };
  emit.wants_depth = [this](const std::string& kind) { return server_->has_subscribers("depth:" + kind); };
  emit.depth = [this](const protocol::DepthEvent& e) {
    server_->publish("depth:" + e.kind, protocol::encode_depth(e));
  };
  pipeline_->set_emitter(std::move(emit));
}

Daemon::~Daemon() { stop(); }

void Daemon::start() {
  started_ns_ = protocol::monotonic_ns();
  // Every thread reports what ends it. Without a server or a pipeline the
  // daemon is of no use: it fails (exit status 1, so systemd restarts it).
  // A source that fails leaves the daemon serving status, which says why.
  // (Named, so that top -H and ps -L say which thread does what.)
  server_thread_ = std::thread([this] {
    ::pthread_setname_np(::pthread_self(), "tofmatd-server");
    try {
      server_->run(stop_);
    } catch (const std::exception& e) {
      fail("the server stopped: " + std::string(e.what()));
    }
  });
  pipeline_thread_ = std::thread([this] {
    ::pthread_setname_np(::pthread_self(), "tofmatd-process");
    try {
      pipeline_->run(stop_);
    } catch (const std::exception& e) {
      fail("processing stopped: " + std::string(e.what()));
    }
  });
  if (line_) {
    // Without its thread the line would push nothing and reject nothing: the
    // daemon fails (systemd restarts it) rather than run a line blind.
    line_thread_ = std::thread([this] {
      ::pthread_setname_np(::pthread_self(), "tofmatd-line");
      try {
        line_->run(stop_);
      } catch (const std::exception& e) {
        fail("the sorting line stopped: " + std::string(e.what()));
      }
    });
  }
  if (button_) {
    // A broken button leaves the labels served: it is reported (log, status).
    button_thread_ = std::thread([this] {
      ::pthread_setname_np(::pthread_self(), "tofmatd-button");
      try {
        button_->run(stop_);
      } catch (const std::exception& e) {
        logger(LogCategory::kGpio).error("the reset button stopped: {}", e.what());
        button_->stopped(e.what());
      }
    });
  }
  source_thread_ = std::thread([this] {
    ::pthread_setname_np(::pthread_self(), "tofmatd-source");
    SourceCallbacks cb;
    cb.region = [this] { return pipeline_->wanted_region(); };
    cb.raw_buffer = [this] { return pipeline_->raw_buffer(); };
    cb.frame = [this](RawFrame&& f) {
      if (source_->lossless())
        pipeline_->push_wait(std::move(f), stop_);
      else
        pipeline_->push(std::move(f));
    };
    cb.state = [this](DeviceState s, const std::string& message) {
      {
        std::lock_guard<std::mutex> lock(state_mutex_);
        if (s == device_state_ && message == device_message_) return;
        device_state_ = s;
        device_message_ = message;
        ++device_changes_;
      }
      logger(LogCategory::kKinect).info("device {}: {}", device_state_name(s), message);
      if (line_) line_->camera(s == DeviceState::kStreaming);
      protocol::Message m;
      m.meta = {{"event", "device"},
                {"state", device_state_name(s)},
                {"message", message.substr(0, protocol::kMaxTextBytes)},  // (a driver's text is not bounded)
                {"timestamp_ns", protocol::monotonic_ns()}};
      server_->publish("device", m);
    };
    try {
      source_->run(cb, stop_);
    } catch (const std::exception& e) {
      logger(LogCategory::kKinect).error("the source stopped: {}", e.what());
      cb.state(DeviceState::kFailed, e.what());
    }
  });
  logger(LogCategory::kDaemon)
      .info("{} serving: source {}, profile {}, table {}", kVersion, source_->describe(), options_.profile.name,
            options_.table);
  if (source_->simulated())
    logger(LogCategory::kDaemon)
        .warn("the source is SIMULATED: its labels are not a camera's (every label and status say so)");
}

void Daemon::publish_reset(const char* by, std::uint64_t timestamp_ns) {
  protocol::Message m;
  m.meta = {{"event", "reset"}, {"by", by}, {"timestamp_ns", timestamp_ns}};
  server_->publish("reset", m);
}

void Daemon::fail(const std::string& why) {
  logger(LogCategory::kDaemon).critical("{}", why);
  failed_ = true;
  ::kill(::getpid(), SIGTERM);  // main's sigwait takes it: a clean stop, then exit status 1
}

void Daemon::stop() {
  stop_ = true;
  if (server_) server_->wake();
  if (line_) line_->wake();
  if (button_) button_->wake();
  for (auto* t : {&source_thread_, &pipeline_thread_, &server_thread_, &line_thread_, &button_thread_})
    if (t->joinable()) t->join();
}

bool Daemon::reload_table() {
  const std::string path = pipeline_->table_path();
  try {
    pipeline_->set_table(load_table_file(path), path);
    server_->forget("labels");  // (`latest` serves no label of the old table)
    logger(LogCategory::kDaemon).info("reloaded table {}", path);
    std::lock_guard<std::mutex> lock(state_mutex_);
    last_reload_ = {{"ok", true}, {"path", path}};
    return true;
  } catch (const std::exception& e) {
    logger(LogCategory::kDaemon).error("table {} not reloaded, the old one keeps serving: {}", path, e.what());
    std::lock_guard<std::mutex> lock(state_mutex_);
    last_reload_ = {{"ok", false}, {"path", path}, {"error", e.what()}};
    return false;
  }
}

nlohmann::json Daemon::status() const {
  auto s = pipeline_->status();
  std::lock_guard<std::mutex> lock(state_mutex_);
  s["server"] = kVersion;
  s["source"] = source_->describe();
  s["simulated"] = source_->simulated();
  s["source_counters"] = source_->counters();
  s["device"] = {
      {"state", device_state_name(device_state_)}, {"message", device_message_}, {"changes", device_changes_}};
  s["clients"] = server_->status();
  s["uptime_s"] = static_cast<double>(protocol::monotonic_ns() - started_ns_) * 1e-9;
  s["last_reload"] = last_reload_;
  if (line_) s["line"] = line_->status();
  if (button_) s["button"] = button_->status();
  return s;
}

protocol::Reply Daemon::handle(const protocol::Request& req) {
  namespace codes = protocol::codes;
  protocol::Reply r;
  r.id = req.id;
  const auto& a = req.args;
  try {
    if (req.cmd == "status") {
      r.result = status();
    } else if (req.cmd == "reset") {
      // session (minor 10): also a new session for the session matcher's learning
      const bool session = a.contains("session") && protocol::get_bool(a, "session");
      pipeline_->reset();
      if (session) pipeline_->reset_session();
      server_->forget("labels");
      publish_reset("command", protocol::monotonic_ns());
    } else if (req.cmd == "set_profile") {
      pipeline_->set_profile(protocol::get_string(a, "name", protocol::kMaxNameBytes));
      server_->forget("labels");
    } else if (req.cmd == "set_roi") {
      PixelRegion roi;
      roi.x0 = static_cast<int>(protocol::get_int(a, "x0", 0, kWidth));
      roi.y0 = static_cast<int>(protocol::get_int(a, "y0", 0, kHeight));
      roi.x1 = static_cast<int>(protocol::get_int(a, "x1", 0, kWidth));
      roi.y1 = static_cast<int>(protocol::get_int(a, "y1", 0, kHeight));
      pipeline_->set_roi(roi);
      server_->forget("labels");
    } else if (req.cmd == "set_candidates") {
      pipeline_->set_candidates(
          protocol::get_string_list(a, "materials", protocol::kMaxMaterials, protocol::kMaxNameBytes));
      server_->forget("labels");
    } else if (req.cmd == "load_table") {
      const std::string path = table_in(options_.table_dir, protocol::get_string(a, "path", protocol::kMaxTextBytes));
      std::shared_ptr<const ExemplarTable> table;
      try {
        table = load_table_file(path);
      } catch (const std::exception& e) {
        return failure(req.id, codes::kFailed,
                       "table \"" + path + "\" not loaded (the old one keeps serving): " + e.what());
      }
      pipeline_->set_table(table, path);
      server_->forget("labels");
      r.result = {{"materials", table->materials()}};
    } else if (req.cmd == "trigger") {
      if (line_)
        return failure(
            req.id, codes::kInvalidArgument,
            "the light barrier triggers this sorting line; a trigger from a client would take an item's burst");
      const int burst = a.contains("burst") ? static_cast<int>(protocol::get_int(a, "burst", 1, 300)) : 0;
      r.result = {{"trigger", pipeline_->trigger(burst)}};
    } else {
      return failure(req.id, codes::kUnknownCommand, "unknown command \"" + req.cmd + "\"");
    }
  } catch (const protocol::ProtocolError& e) {  // a bad argument
    return failure(req.id, codes::kInvalidArgument, e.what());
  } catch (const std::logic_error& e) {  // refused by the pipeline (invalid_argument), or a trigger outside sorting
    return failure(req.id, codes::kInvalidArgument, e.what());
  }
  return r;
}

}  // namespace tofmat::daemon
