// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd: the daemon's entry point. Signals are taken synchronously on this
// thread (blocked everywhere else): SIGTERM/SIGINT stop cleanly, SIGHUP
// reloads the table.
#include <signal.h>

#include <cstdio>

#include "tofmat/daemon/log.hpp"
#include "tofmat/daemon/options.hpp"

int main(int argc, char** argv) {
  int exit_code = 0;
  auto cl = tofmat::daemon::parse_command_line(argc, argv, exit_code);
  if (!cl) return exit_code;
  // Logs on stderr by category (the levels were checked with the options);
  // under systemd with syslog priorities and the journal's own timestamps.
  using tofmat::daemon::LogCategory;
  tofmat::daemon::setup_logging(tofmat::daemon::parse_log_levels(cl->log_level), tofmat::daemon::stderr_is_journal());
  auto& log = tofmat::daemon::logger(LogCategory::kDaemon);

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
    log.critical("cannot start: {}", e.what());
    return 1;
  }
  for (;;) {
    int sig = 0;
    if (sigwait(&signals, &sig) != 0) continue;
    if (sig == SIGHUP) {
      daemon->reload_table();
      continue;
    }
    log.info("{}: stopping", daemon->failed() ? "a thread failed" : sig == SIGTERM ? "SIGTERM" : "SIGINT");
    break;
  }
  daemon->stop();
  const bool failed = daemon->failed();
  daemon.reset();
  log.info("stopped");
  return failed ? 1 : 0;
}
