// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd: the daemon's entry point. Signals are taken synchronously on this
// thread (blocked everywhere else): SIGTERM/SIGINT stop cleanly, SIGHUP
// reloads the table.
#include <signal.h>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <cstdio>

#include "tofmat/daemon/options.hpp"

int main(int argc, char** argv) {
  int exit_code = 0;
  auto cl = tofmat::daemon::parse_command_line(argc, argv, exit_code);
  if (!cl) return exit_code;
  // Logs on stderr (journald adds its own timestamps under systemd).
  spdlog::set_default_logger(spdlog::stderr_color_mt("tofmatd"));
  spdlog::set_level(spdlog::level::from_str(cl->log_level));
  spdlog::set_pattern("%Y-%m-%d %H:%M:%S.%e %^%l%$ %v");

  sigset_t signals;
  sigemptyset(&signals);
  for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&signals, s);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);  // before any thread starts: they inherit it
  ::signal(SIGPIPE, SIG_IGN);                     // a client gone mid-send is an error return, not a signal

  std::unique_ptr<tofmat::daemon::Daemon> daemon;
  try {
    daemon = std::make_unique<tofmat::daemon::Daemon>(cl->daemon);
    daemon->start();
  } catch (const std::exception& e) {
    spdlog::critical("cannot start: {}", e.what());
    return 1;
  }
  for (;;) {
    int sig = 0;
    if (sigwait(&signals, &sig) != 0) continue;
    if (sig == SIGHUP) {
      daemon->reload_table();
      continue;
    }
    spdlog::info("{}: stopping", daemon->failed() ? "a thread failed" : sig == SIGTERM ? "SIGTERM" : "SIGINT");
    break;
  }
  daemon->stop();
  const bool failed = daemon->failed();
  daemon.reset();
  spdlog::info("stopped");
  return failed ? 1 : 0;
}
