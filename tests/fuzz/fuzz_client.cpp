// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: the C++ client (firmware/protocol/client.hpp) against a
// scripted daemon that sends whatever the input says. Each input is one
// connection over a socketpair: its bytes are what the "daemon" sends, in
// one go, then its side is shut. The client does the handshake, sends
// "status" (its reply, when the input has one, is id 2), and then takes
// events until there are none.
//
// Oracles:
//  - every failure is a ClientError (no other exception, no crash, no leak);
//  - what the client keeps while a command waits stays within its bounds
//    (small ones here, so the input can reach them): events and bytes;
//  - every error message is printable ASCII (the peer's bytes escaped);
//  - the client returns: the daemon's side is shut, so nothing may block.
#include <sys/socket.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <thread>

#include "tofmat/protocol/client.hpp"
#include "tofmat/protocol/socket.hpp"

namespace {

using namespace tofmat::protocol;

constexpr std::size_t kMaxEvents = 8;
constexpr std::size_t kMaxBytes = 64 * 1024;

void check_printable(const std::string& text) {
  for (const char c : text) {
    const auto b = static_cast<unsigned char>(c);
    if (b < 0x20 || b >= 0x7f) std::abort();
  }
}

void check_bounds(const Client& client) {
  if (client.pending_events() > kMaxEvents || client.pending_bytes() > kMaxBytes) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  int ends[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, ends) != 0) return 0;
  Fd daemon_side(ends[0]);
  Fd client_side(ends[1]);
  // The daemon's bytes from a thread (they may not fit the socket's buffer),
  // which also reads and discards what the client sends so it never blocks.
  std::thread daemon([&] {
    std::size_t sent = 0;
    while (sent < size) {
      const ssize_t n = ::send(daemon_side.get(), data + sent, size - sent, MSG_NOSIGNAL);
      if (n <= 0) break;
      sent += static_cast<std::size_t>(n);
    }
    ::shutdown(daemon_side.get(), SHUT_WR);
    char sink[4096];
    while (::recv(daemon_side.get(), sink, sizeof sink, 0) > 0) {
    }
  });
  ClientOptions options;
  options.timeout_ms = 2000;
  options.max_pending_events = kMaxEvents;
  options.max_pending_bytes = kMaxBytes;
  Address address;
  address.path = "fuzz";
  try {
    Client client(std::move(client_side), address, options);
    try {
      (void)client.request("status");
    } catch (const ClientError& e) {
      check_printable(e.what());
    }
    check_bounds(client);
    try {
      while (client.next_event(0)) check_bounds(client);
    } catch (const ClientError& e) {
      check_printable(e.what());
    }
    client.close();
  } catch (const ClientError& e) {
    check_printable(e.what());
  }
  ::shutdown(daemon_side.get(), SHUT_RDWR);
  daemon.join();
  return 0;
}
