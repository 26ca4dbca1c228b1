// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Sockets for tofmatd and its clients: a Unix stream socket by default
// (permissions 0660: the group decides who may connect), TCP only when asked.
// Thin RAII over the POSIX calls; errors are SocketError with the OS reason.
#pragma once
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

struct pollfd;  // <poll.h>

namespace tofmat::protocol {

class SocketError : public std::runtime_error {
 public:
  SocketError(const std::string& what, int os_error) : std::runtime_error(what), os_error_(os_error) {}
  int os_error() const { return os_error_; }  // errno (ECONNREFUSED, ENOENT, ...), 0 if none

 private:
  int os_error_;
};

class Fd {
 public:
  Fd() = default;
  explicit Fd(int fd) : fd_(fd) {}
  ~Fd();
  Fd(Fd&& o) noexcept : fd_(o.release()) {}
  Fd& operator=(Fd&& o) noexcept;
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int get() const { return fd_; }
  int release() {
    const int f = fd_;
    fd_ = -1;
    return f;
  }
  explicit operator bool() const { return fd_ >= 0; }
  void reset();

 private:
  int fd_ = -1;
};

// An eventfd that wakes a thread blocked in poll from any other thread (the
// server's, the sorting line's and the reset button's stop and inbox).
class WakeFd {
 public:
  WakeFd();  // throws SocketError
  int get() const { return fd_.get(); }
  void wake();   // any thread; never blocks
  void drain();  // the polling thread, once poll says it is readable

 private:
  Fd fd_;
};

// "host:port" (TCP) or anything else (a Unix socket path). A path containing
// ':' can be given as "unix:PATH".
struct Address {
  bool tcp = false;
  std::string path;  // Unix
  std::string host;  // TCP
  std::uint16_t port = 0;
  std::string describe() const;
};
Address parse_address(const std::string& text);  // throws std::invalid_argument

// The Unix listener's backlog: connections the kernel holds for the server.
constexpr int kUnixBacklog = 64;

// Listening sockets, non-blocking, close-on-exec. listen_unix replaces a
// stale socket file (one nobody answers on) and refuses to replace a live one
// or anything that is not a socket.
Fd listen_unix(const std::string& path, unsigned mode = 0660);
Fd listen_tcp(const std::string& host, std::uint16_t port);
std::uint16_t local_port(int fd);  // the port a TCP socket is bound to (tests bind port 0)

// A blocking connection with a timeout on the connect.
Fd connect_to(const Address& address, int timeout_ms);

void set_nonblocking(int fd);
// Waits until fd is readable (or writable); false on timeout (timeout_ms < 0: forever).
bool wait_readable(int fd, int timeout_ms);
bool wait_writable(int fd, int timeout_ms);
// Writes all of data within timeout_ms. Throws SocketError on error, timeout or a closed peer.
void write_all(int fd, const std::uint8_t* data, std::size_t size, int timeout_ms);

std::uint64_t monotonic_ns();  // CLOCK_MONOTONIC: timestamps both sides compare
// Waits (ppoll, to the nanosecond) until one of `fds` is ready or
// monotonic_ns() reaches `until_ns`; a signal ends the wait early. Throws
// SocketError if the poll fails.
void poll_until(::pollfd* fds, std::size_t count, std::uint64_t until_ns);

}  // namespace tofmat::protocol
